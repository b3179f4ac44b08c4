"""A real headless Chromium driven over the DevTools protocol (Debian's ``chromium`` package).

``ensure_chromium`` installs the package with apt-get when no browser is on the PATH (the test
setup of a fresh Debian machine, as ``make setup`` does for PoCL). ``load`` opens a page, waits for
its load event and returns the console errors, uncaught exceptions and failed loads it reported,
values evaluated in the page and a PNG screenshot of the whole page.
"""
from __future__ import annotations

import base64
import json
import os
import shutil
import signal
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path

from tests.debian_packages import apt_install

BROWSERS = ("chromium", "chromium-browser")


def ensure_chromium() -> str:
    """The browser's path, installing Debian's chromium with apt-get when it is missing."""
    for name in BROWSERS:
        if shutil.which(name):
            return shutil.which(name)
    apt_install("chromium")
    path = shutil.which("chromium")
    if path is None:
        raise RuntimeError("apt-get installed chromium but it is not on the PATH")
    return path


class _Session:
    def __init__(self, ws_url: str):
        import websocket

        self.ws = websocket.create_connection(ws_url, timeout=60, suppress_origin=True)
        self.next_id, self.events = 0, []

    def call(self, method: str, **params) -> dict:
        self.next_id += 1
        self.ws.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv())
            if msg.get("id") == self.next_id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})
            self.events.append(msg)

    def wait_for(self, method: str, timeout: float = 60.0) -> dict:
        deadline = time.monotonic() + timeout
        for i, e in enumerate(self.events):
            if e.get("method") == method:
                return self.events.pop(i)
        while time.monotonic() < deadline:
            msg = json.loads(self.ws.recv())
            if msg.get("method") == method:
                return msg
            self.events.append(msg)
        raise TimeoutError(method)


def load(url: str, expressions: dict[str, str], width: int = 1280, height: int = 900) -> dict:
    """Open ``url`` in headless Chromium; returns ``errors`` (console errors, exceptions, failed
    requests), ``values`` (each expression evaluated after the load event) and ``png`` (bytes)."""
    browser = ensure_chromium()
    # Chromium's helper processes (crashpad, zygote) may still write into the profile while it is
    # removed ("Directory not empty: 'Default'", seen once in make test): they are stopped with the
    # browser's process group below, and a straggler's file does not fail the test
    with tempfile.TemporaryDirectory(ignore_cleanup_errors=True) as profile:
        proc = subprocess.Popen([browser, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                                 "--disable-extensions", "--remote-debugging-port=0", f"--user-data-dir={profile}",
                                 f"--window-size={width},{height}", "about:blank"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        try:
            port_file = Path(profile) / "DevToolsActivePort"
            deadline = time.monotonic() + 60
            while not (port_file.is_file() and port_file.read_text().strip()):
                if time.monotonic() > deadline or proc.poll() is not None:
                    raise RuntimeError("chromium did not start its DevTools server")
                time.sleep(0.1)
            port = int(port_file.read_text().split()[0])
            targets = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=30).read())
            page = next(t for t in targets if t.get("type") == "page")
            s = _Session(page["webSocketDebuggerUrl"])
            for domain in ("Page", "Runtime", "Log", "Network"):
                s.call(f"{domain}.enable")
            s.call("Emulation.setDeviceMetricsOverride", width=width, height=height, deviceScaleFactor=1,
                   mobile=False)
            s.call("Page.navigate", url=url)
            s.wait_for("Page.loadEventFired", timeout=120)
            values = {k: s.call("Runtime.evaluate", expression=e, returnByValue=True,
                                awaitPromise=True)["result"].get("value") for k, e in expressions.items()}
            metrics = s.call("Page.getLayoutMetrics")
            full = metrics.get("cssContentSize") or metrics["contentSize"]
            shot = s.call("Page.captureScreenshot", format="png", captureBeyondViewport=True,
                          clip={"x": 0, "y": 0, "width": width, "height": min(int(full["height"]), 16000),
                                "scale": 1})
            s.call("Runtime.evaluate", expression="1")  # drain events that arrived meanwhile
            errors = []
            for e in s.events:
                m, p = e.get("method"), e.get("params", {})
                if m == "Runtime.exceptionThrown":
                    errors.append(f"exception: {p['exceptionDetails'].get('text')}")
                elif m == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
                    errors.append(f"console.{p['type']}: {p.get('args')}")
                elif m == "Log.entryAdded" and p["entry"].get("level") == "error":
                    errors.append(f"log: {p['entry'].get('text')} {p['entry'].get('url', '')}")
                elif m == "Network.loadingFailed":
                    errors.append(f"load failed: {p.get('errorText')}")
            s.ws.close()
            return {"errors": errors, "values": values, "png": base64.b64decode(shot["data"])}
        finally:
            _signal_group(proc, signal.SIGTERM)
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                _signal_group(proc, signal.SIGKILL)
                proc.wait()


def _signal_group(proc: subprocess.Popen, sig: int) -> None:
    """Signal the browser and every helper it started (its own process group: start_new_session in load)."""
    try:
        os.killpg(proc.pid, sig)
    except ProcessLookupError:
        pass
