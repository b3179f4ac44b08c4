"""Kill anywhere (slow): a ROOM render SIGKILLed at 20 random moments, rerun after each, ends with
the frames, records and photon store of an uninterrupted run and no temporary file; the same with
one Dask worker killed in the middle of a segment."""
from __future__ import annotations

import json
import random
import signal
import subprocess
import sys
import time

import pytest

from pipeline.frames.images import frame_paths
from pipeline.segments.records import read_records
from tests.run.shoot_helpers import store_fingerprint
from tests.run.test_shoot_distributed import dask_cluster  # noqa: F401  (the fixture)

pytestmark = [pytest.mark.slow, pytest.mark.timeout(3600)]  # minutes of rendering, not a hang
CHEAP = {"pilot_photons": 2000, "n_frame_min": 1000, "n_frame_max": 16000, "d_thr": 0.45,
         "fmax_initial": 6, "fmax_step": 4, "fmax_cap": 10}
LOOM = [sys.executable, "-m", "pipeline"]


def _command(tmp, name, *extra):
    return [*LOOM, "render", str(tmp / "room.glb"), "--frames", "60-80", "--out", str(tmp / name),
            "--resolution", "48x36", "--spp", "1", "--config", str(tmp / "c.json"), "--quiet", *extra]


def _result(out):
    frames = {f: [p.read_bytes() for p in frame_paths(out, f)] for f in range(60, 81)}
    return frames, [r.without_times() for r in read_records(out)], store_fingerprint(str(out / "photons.zarr"))


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("kill")
    subprocess.run([*LOOM, "scene", "room", "-o", str(tmp / "room.glb")], check=True, capture_output=True)
    (tmp / "c.json").write_text(json.dumps(CHEAP))
    t0 = time.monotonic()
    subprocess.run(_command(tmp, "ref", "--scheduler", "synchronous"), check=True, capture_output=True)
    return tmp, time.monotonic() - t0, _result(tmp / "ref")


def test_twenty_kills_at_random_moments(reference):
    # Each trial: a fresh render killed at a random moment of its run (pilot, F_max and AQM steps,
    # photon batches being written, reconstruction, frames being written), then rerun to the end.
    import shutil

    tmp, duration, want = reference
    rng = random.Random(20)
    killed = 0
    for trial in range(20):
        name = f"killed-{trial:02d}"
        proc = subprocess.Popen(_command(tmp, name, "--scheduler", "synchronous"),
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        moment = rng.uniform(0.1, 0.9) * duration  # the reference ran with cold caches: a bit slower
        try:
            proc.wait(timeout=moment)
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGKILL)
            proc.wait()
        killed += proc.returncode == -signal.SIGKILL
        rerun = subprocess.run(_command(tmp, name, "--scheduler", "synchronous"), capture_output=True, text=True)
        assert rerun.returncode == 0, f"trial {trial}: killed at {moment:.1f} s, the rerun failed: {rerun.stderr}"
        assert _result(tmp / name) == want, f"trial {trial}: killed at {moment:.1f} s"
        assert not list((tmp / name).rglob("*partial*"))  # in the frames folder and the store
        shutil.rmtree(tmp / name)
    assert killed >= 16, f"only {killed} of 20 runs were cut short (the reference took {duration:.1f} s)"


def test_a_worker_killed_mid_segment(reference, dask_cluster):  # noqa: F811
    tmp, _, want = reference
    address, workers = dask_cluster
    proc = subprocess.Popen(_command(tmp, "worker", "--scheduler", address), stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None:
        if (tmp / "worker" / "segments" / "segment-000.json").exists():
            workers[0].send_signal(signal.SIGKILL)
            break
        time.sleep(0.02)
    _, err = proc.communicate(timeout=600)
    assert proc.returncode == 0, err
    assert workers[0].poll() is not None  # it was killed while the render went on
    assert _result(tmp / "worker") == want
