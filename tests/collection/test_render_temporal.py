"""``loom render --temporal adaptive|fixed|off --fmax N``: the indirect maps come from the temporal
windows (pipeline/collection/maps.py), and bad options fail with one line."""
from __future__ import annotations

import numpy as np
from click.testing import CliRunner

from pipeline.cli import main
from pipeline.scene.builtin import write_builtin
from pipeline.store.illumination import IlluminationMaps

FRAMES = (60, 67)


def render(tmp_path, scene, mode, fmax="30"):
    out = tmp_path / mode
    result = CliRunner().invoke(main, [
        "render", str(scene), "--frames", f"{FRAMES[0]}-{FRAMES[1]}", "--out", str(out),
        "--resolution", "32x24", "--spp", "1", "--photons", "20000", "--scheduler", "synchronous",
        "--quiet", "--temporal", mode, "--fmax", fmax])
    return result, out


def test_render_temporal_modes_write_their_maps(tmp_path):
    scene = write_builtin("room", tmp_path / "room.glb")
    maps = {}
    for mode in ("off", "adaptive"):
        result, out = render(tmp_path, scene, mode)
        assert result.exit_code == 0, result.output
        store = IlluminationMaps.open(str(out / "photons.zarr"))
        maps[mode] = np.stack([store.read(f - 1) for f in range(FRAMES[0], FRAMES[1] + 1)]).astype(np.float64)
        assert (out / "beauty.0060.png").exists()
    # Same photons, same direct maps; the adaptive indirect maps pool neighbours: far less flicker
    flicker = {m: np.abs(np.diff(v, axis=0)).mean() / v.mean() for m, v in maps.items()}
    assert flicker["adaptive"] < 0.5 * flicker["off"], flicker


def test_render_refuses_a_bad_fmax(tmp_path):
    scene = write_builtin("room", tmp_path / "room.glb")
    result, _ = render(tmp_path, scene, "fixed", fmax="-2")
    assert result.exit_code == 2 and "--fmax" in result.output
