"""Nothing left behind: a killed ``loom shoot`` leaves temp files in the store that
its rerun removes, with the store then equal to an uninterrupted run's; a refused command creates
no store and no output folder."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.run.shoot_helpers import store_fingerprint

ROOT = Path(__file__).resolve().parents[2]
LOOM = [sys.executable, "-m", "pipeline"]
ENV = dict(os.environ, PYTHONPATH=str(ROOT))


def _shoot(scene, store, *extra, check=True):
    return subprocess.run([*LOOM, "shoot", str(scene), "--store", str(store), "--frames", "1-6", "--photons",
                           "60000", "--scheduler", "synchronous", "--quiet", *extra],
                          capture_output=True, text=True, env=ENV, check=check)


@pytest.fixture(scope="module")
def cornell(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("leftovers")
    subprocess.run([*LOOM, "scene", "cornell", "-o", str(tmp / "cornell.glb")], check=True, env=ENV,
                   capture_output=True)
    _shoot(tmp / "cornell.glb", tmp / "reference.zarr")
    return tmp, store_fingerprint(str(tmp / "reference.zarr"))


def test_rerun_of_a_killed_shoot_removes_its_temp_files(cornell):
    tmp, want = cornell
    store = tmp / "killed.zarr"
    proc = subprocess.Popen([*LOOM, "shoot", str(tmp / "cornell.glb"), "--store", str(store), "--frames", "1-6",
                             "--photons", "60000", "--scheduler", "synchronous", "--quiet"],
                            env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    # Kill it once it has written its first batch (batch/c.f.b), mid-run
    deadline = time.monotonic() + 300
    while proc.poll() is None and time.monotonic() < deadline:
        if any(store.glob("batch/c.*")):
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    assert proc.wait() == -signal.SIGKILL, "the shoot ended before it could be killed"
    # What a writer killed between its temp file and the rename leaves (pipeline/store: set_many)
    batches = [p for p in store.rglob("*") if p.is_dir()]
    assert batches, "the shoot was killed before it created its store"
    for i, folder in enumerate(batches[:3]):
        (folder / f".c.{4242 + i}.deadbeef.partial").write_bytes(b"half a chunk")
    assert list(store.rglob("*.partial"))
    _shoot(tmp / "cornell.glb", store)
    assert not list(store.rglob("*.partial"))
    assert store_fingerprint(str(store)) == want


@pytest.mark.parametrize("args, says", [
    (["--workers", "0", "--scheduler", "local"], "--workers"),
    (["--workers", "-1", "--scheduler", "local"], "--workers"),
    (["--frames", "1-1000000000"], "frames"),
    (["--scheduler", "nowhere"], "--scheduler"),
])
def test_a_refused_shoot_creates_no_store(cornell, args, says):
    tmp, _ = cornell
    store = tmp / f"refused{abs(hash(tuple(args)))}.zarr"
    proc = _shoot(tmp / "cornell.glb", store, *args, check=False)
    assert proc.returncode == 2 and says in proc.stderr and proc.stderr.count("\n") == 1, proc.stderr
    assert not store.exists()


@pytest.mark.slow
def test_an_unreachable_scheduler_leaves_no_store_and_no_output(cornell):
    tmp, _ = cornell
    proc = _shoot(tmp / "cornell.glb", tmp / "unreached.zarr", "--scheduler", "tcp://127.0.0.1:9", check=False)
    assert proc.returncode == 2 and "cannot reach the scheduler" in proc.stderr
    assert not (tmp / "unreached.zarr").exists()
    proc = subprocess.run([*LOOM, "render", str(tmp / "cornell.glb"), "--out", str(tmp / "unreached"),
                           "--scheduler", "tcp://127.0.0.1:9", "--quiet"], capture_output=True, text=True, env=ENV)
    assert proc.returncode == 2 and not (tmp / "unreached").exists()
