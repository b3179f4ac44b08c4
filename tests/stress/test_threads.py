"""Identical results across PoCL thread counts and 1, 2 and 3 Dask workers (docs/04-photons.md §6).

Each render runs ``loom render`` in a subprocess of its own with PoCL's thread count set in its
environment (POCL_MAX_PTHREAD_COUNT for the pthread device, POCL_CPU_MAX_CU_COUNT for the cpu
device of PoCL >= 4): the kernels (emission, bounce, temporal windows, gather, filter, camera,
surface lookup) and the photon store must give the same bits, and so must a LocalCluster of 1, 2
or 3 workers. Compared: every batch's done marker (record digest), the stored illumination maps
and every frame's EXR and PNG, byte for byte.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pipeline.store import PhotonStore
from pipeline.store.illumination import IlluminationMaps
from tests.stress.scenes import lit_room

FRAMES = 4
ROOT = Path(__file__).resolve().parents[2]


def _env(threads: int) -> dict:
    return dict(os.environ, PYTHONPATH=str(ROOT), POCL_MAX_PTHREAD_COUNT=str(threads),
                POCL_CPU_MAX_CU_COUNT=str(threads))


def _compute_units(threads: int) -> int:
    """The compute units PoCL's device reports under ``threads``: proof that the variables work."""
    code = "from kernels.context import device_context; print(device_context()[0].devices[0].max_compute_units)"
    done = subprocess.run([sys.executable, "-c", code], env=_env(threads), capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    return int(done.stdout.split()[-1])


def _render(scene, out, threads: int, *scheduler: str) -> dict:
    env = _env(threads)
    cmd = [sys.executable, "-m", "pipeline", "render", str(scene), "--out", str(out), "--frames", f"1-{FRAMES}",
           "--photons", "20000", "--fmax", "4", "--resolution", "40x30", "--spp", "1", "--quiet", *scheduler]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    store = PhotonStore.open(str(out / "photons.zarr"))
    maps = IlluminationMaps.open(str(out / "photons.zarr"))
    return dict(
        markers=[store.batch_info(f, b) for f in range(FRAMES) for b in store.done_batches(f)],
        maps=[maps.read(f, name) for f in range(FRAMES) for name in ("indirect", "direct")],
        files={p.name: p.read_bytes() for p in sorted(out.glob("beauty.*"))})


def _assert_same(a: dict, b: dict) -> None:
    assert a["markers"] == b["markers"] and len(a["markers"]) >= FRAMES
    for x, y in zip(a["maps"], b["maps"]):
        np.testing.assert_array_equal(x, y)
    assert a["files"].keys() == b["files"].keys() and len(a["files"]) == 2 * FRAMES
    assert all(a["files"][k] == b["files"][k] for k in a["files"])


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    return lit_room(tmp_path_factory.mktemp("threads") / "room.glb", frames=FRAMES)


def test_same_bits_with_one_or_three_pocl_threads(scene, tmp_path):
    assert (_compute_units(1), _compute_units(3)) == (1, 3)
    one = _render(scene, tmp_path / "t1", 1, "--scheduler", "synchronous")
    three = _render(scene, tmp_path / "t3", 3, "--scheduler", "synchronous")
    _assert_same(one, three)


@pytest.mark.slow
def test_same_bits_on_one_two_and_three_workers(scene, tmp_path):
    runs = [_render(scene, tmp_path / f"w{n}", n, "--scheduler", "local", "--workers", str(n)) for n in (1, 2, 3)]
    _assert_same(runs[0], runs[1])
    _assert_same(runs[0], runs[2])
