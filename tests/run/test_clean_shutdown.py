"""A successful render on a local Dask cluster ends quietly: the cluster is closed so that no
worker heartbeat outlives it (pipeline/run/cluster.py close_local), and stderr holds no traceback."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from tests.frames.scenes import plane_scene

RENDERS = 4


def test_several_local_cluster_renders_print_no_traceback(tmp_path):
    scene = plane_scene(tmp_path / "plane.glb", frames=2)
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    for i in range(RENDERS):
        out = tmp_path / f"out{i}"
        run = subprocess.run([sys.executable, "-m", "pipeline", "render", str(scene), "--out", str(out),
                              "--frames", "1-2", "--photons", "2000", "--resolution", "24x16", "--workers", "2",
                              "--scheduler", "local"], capture_output=True, text=True, env=env, timeout=300)
        assert run.returncode == 0, run.stderr
        assert "Traceback" not in run.stderr and "CommClosedError" not in run.stderr, run.stderr
        assert "distributed." not in run.stderr, run.stderr  # nor a log line of the shutdown
        assert (out / "beauty.0002.png").is_file()
