"""`loom render --scheduler tcp://...` against a `dask scheduler` and two `dask worker` processes
started from the command line on 127.0.0.1: the same records and frames as the synchronous run,
Dask's performance report, and a clear error when nothing listens."""
from __future__ import annotations

import json
import subprocess
import sys
import time

from pipeline.frames.images import frame_paths
from pipeline.segments.records import read_records
from tests.run.test_shoot_distributed import dask_cluster  # noqa: F401  (the fixture)

CHEAP = {"pilot_photons": 2000, "n_frame_min": 1000, "n_frame_max": 8000, "d_thr": 0.45,
         "fmax_initial": 6, "fmax_step": 4, "fmax_cap": 10}
LOOM = [sys.executable, "-m", "pipeline"]


def _render(tmp_path, name, *extra):
    scene = tmp_path / "room.glb"
    if not scene.exists():
        subprocess.run([*LOOM, "scene", "room", "-o", str(scene)], check=True, capture_output=True)
        (tmp_path / "c.json").write_text(json.dumps(CHEAP))
    out = tmp_path / name
    result = subprocess.run([*LOOM, "render", str(scene), "--frames", "60-75", "--out", str(out), "--resolution",
                             "48x36", "--spp", "1", "--config", str(tmp_path / "c.json"), *extra],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    return out, result


def test_render_on_command_line_dask_processes(dask_cluster, tmp_path):  # noqa: F811
    address, _ = dask_cluster
    ref, _ = _render(tmp_path, "sync", "--scheduler", "synchronous")
    out, result = _render(tmp_path, "tcp", "--scheduler", address, "--performance-report", str(tmp_path / "p.html"))
    assert [r.without_times() for r in read_records(out)] == [r.without_times() for r in read_records(ref)]
    for f in range(60, 76):
        assert [p.read_bytes() for p in frame_paths(out, f)] == [p.read_bytes() for p in frame_paths(ref, f)]
    assert "<html" in (tmp_path / "p.html").read_text()[:2000].lower()


def test_a_scheduler_with_nothing_listening_is_a_clear_error(tmp_path):
    t0 = time.monotonic()
    result = subprocess.run([*LOOM, "render", str(tmp_path / "x.glb"), "--out", str(tmp_path / "o"),
                             "--scheduler", "tcp://127.0.0.1:9"], capture_output=True, text=True)
    assert time.monotonic() - t0 < 30
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
    assert "--scheduler" in result.stderr and not (tmp_path / "o").exists()
