"""Shooting on a real Dask cluster: a `dask scheduler` and two `dask worker` processes on 127.0.0.1.

The store must equal a synchronous run bit for bit, also when a worker is SIGKILLed mid-run.
"""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from pipeline.config import PhotonConfig
from pipeline.run.cluster import WORKER_ENV
from pipeline.run.shoot import plan, shoot
from pipeline.scene import read_scene
from tests.run.shoot_helpers import store_fingerprint

DASK = str(Path(sys.executable).with_name("dask"))
FRAMES, PHOTONS = "1-16", 30_000


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_for_workers(address: str, n: int, timeout: float = 60) -> None:
    from distributed import Client

    with Client(address, timeout="30s") as client:
        client.wait_for_workers(n, timeout=timeout)


@pytest.fixture
def dask_cluster(tmp_path):
    """A scheduler and two single-threaded workers without nannies (so SIGKILL really kills one)."""
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, **WORKER_ENV}
    logs = open(tmp_path / "cluster.log", "w")
    procs = [subprocess.Popen([DASK, "scheduler", "--host", "127.0.0.1", "--port", str(port),
                               "--no-dashboard"], env=env, stdout=logs, stderr=logs)]
    for i in range(2):
        procs.append(subprocess.Popen(
            [DASK, "worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard",
             "--name", f"w{i}", "--host", "127.0.0.1"], env=env, stdout=logs, stderr=logs))
    try:
        _wait_for_workers(address, 2)
        yield address, procs[1:]
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.terminate()
        for p in procs:
            try:
                p.wait(timeout=5)  # a worker whose scheduler is gone may linger past SIGTERM: then SIGKILL
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        logs.close()


@pytest.fixture(scope="module")
def cornell(tmp_path_factory):
    from pipeline.scene.builtin import write_builtin

    return str(write_builtin("cornell", tmp_path_factory.mktemp("scene") / "cornell.glb"))


@pytest.fixture(scope="module")
def synchronous_store(cornell, tmp_path_factory):
    url = str(tmp_path_factory.mktemp("sync") / "sync.zarr")
    shoot(plan(read_scene(cornell), FRAMES, PHOTONS, PhotonConfig()), url, scheduler="synchronous", progress=False)
    return url


def test_cluster_run_equals_synchronous_run(dask_cluster, cornell, synchronous_store, tmp_path):
    address, _ = dask_cluster
    url = str(tmp_path / "cluster.zarr")
    summary = shoot(plan(read_scene(cornell), FRAMES, PHOTONS, PhotonConfig()), url, scheduler=address, progress=False)
    assert summary["tasks"] == 16
    assert store_fingerprint(url) == store_fingerprint(synchronous_store)


def test_worker_killed_mid_run_still_gives_identical_store(dask_cluster, cornell, synchronous_store, tmp_path):
    address, workers = dask_cluster
    url = str(tmp_path / "killed.zarr")
    outcome = {}

    def run():
        try:
            outcome["summary"] = shoot(plan(read_scene(cornell), FRAMES, PHOTONS, PhotonConfig()), url,
                                       scheduler=address, progress=False)
        except BaseException as err:  # reported by the assertion below
            outcome["error"] = err

    thread = threading.Thread(target=run)
    thread.start()
    deadline = time.monotonic() + 120
    killed_at = None
    markers = Path(url) / "batch"
    while time.monotonic() < deadline and thread.is_alive():
        # A batch is one object "c.f.b", its done marker (pipeline/store/__init__.py): listing them is
        # cheap enough to poll every few milliseconds, so the kill lands while batches remain
        # (opening the store at each poll was slow enough to miss a fast run now and then).
        done = len([n for n in os.listdir(markers) if n.startswith("c.")]) if markers.is_dir() else 0
        if done >= 1:
            workers[0].send_signal(signal.SIGKILL)
            killed_at = done
            break
        time.sleep(0.003)
    thread.join(timeout=300)
    assert killed_at is not None and killed_at < 16, "the run ended before a worker could be killed"
    assert workers[0].wait(timeout=10) == -signal.SIGKILL
    assert "error" not in outcome, outcome.get("error")
    assert store_fingerprint(url) == store_fingerprint(synchronous_store)
