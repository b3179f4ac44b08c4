"""Real Khronos sample models (tests/scene/khronos/, source and licence in its README) read, described
and rendered with the renderer's defaults: RiggedSimple, a skinned cylinder bending at its second joint.
The RiggedSimple-like file of tests/scene/deforming_assets.py is its structure written in code; this is
the file itself (Z-up COLLADA export, matrix root, embedded base64 buffer, two joints)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from pipeline.cli import main
from pipeline.frames.images import exr_metadata, frame_is_valid, frame_paths, read_png
from pipeline.scene.gltf import read_gltf

KHRONOS = Path(__file__).resolve().parent / "khronos"
RIGGED_SIMPLE = KHRONOS / "RiggedSimple.gltf"
WIDTH, HEIGHT = 64, 48
# t = (frame - 1) / 30: frame 1 is the rest pose (first key, 0.042 s), frame 32 (1.033 s) is next to the
# full bend (key 1.042 s, the second joint turned 34 deg), frame 63 (2.067 s) is back at rest (key 2.083 s)
FRAMES = (1, 32, 63)


def test_rigged_simple_is_the_sample_file_whole():
    """The shipped copy is the upstream file byte for byte: its size, and every accessor's data has
    the min and max the file declares (a mis-copied base64 run would shift or change them)."""
    assert RIGGED_SIMPLE.stat().st_size == 21061
    doc = read_gltf(RIGGED_SIMPLE)
    assert [len(b) for b in doc.buffers] == [doc.gltf.buffers[0].byteLength] == [6128]
    for i, acc in enumerate(doc.gltf.accessors):
        data = doc.accessor(i, "test").reshape(acc.count, -1)
        assert np.allclose(data.min(0), acc.min, rtol=0, atol=1e-6), i
        assert np.allclose(data.max(0), acc.max, rtol=0, atol=1e-6), i


def test_loom_info_names_the_skin_of_rigged_simple():
    result = CliRunner().invoke(main, ["info", str(RIGGED_SIMPLE)])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert [line for line in lines if line.startswith("deforms")] == [
        "deforms    1 of 1 primitives posed per vertex: node1/Cylinder[0]: skin 0 (2 joints, 2 animated, up to 4 "
        "influences)"]
    assert [line for line in lines if line.startswith("frames")] == ["frames     63 at 30 fps, 2.067 s (frames 1-63)"]


def _green(rgb: np.ndarray) -> np.ndarray:
    """The cylinder's base colour (0.28, 0.64, 0.21) against the grey of the default sky."""
    rgb = rgb[..., :3].astype(int)
    return (rgb[..., 1] > 1.3 * rgb[..., 0]) & (rgb[..., 1] > 1.3 * rgb[..., 2])


def test_rigged_simple_bends_and_straightens_in_the_frames(tmp_path):
    """``loom render`` with its defaults (auto camera, default sun and sky, filmic tone mapping), only
    smaller and with fewer photons: the upper half swings aside at mid-animation and comes back."""
    out = tmp_path / "out"
    result = CliRunner().invoke(main, [
        "render", str(RIGGED_SIMPLE), "--out", str(out), "--frames", ",".join(map(str, FRAMES)),
        "--resolution", f"{WIDTH}x{HEIGHT}", "--spp", "1", "--photons", "3000", "--scheduler", "synchronous",
        "--quiet"])
    assert result.exit_code == 0, result.output
    assert json.loads((out / "report.json").read_text())["rendered"] == list(FRAMES)
    green = []
    for f in FRAMES:
        exr, png = frame_paths(out, f)
        assert frame_is_valid(exr, png, WIDTH, HEIGHT, exr_metadata(exr)["frame_hash"])
        rgb = read_png(png)
        assert rgb.shape == (HEIGHT, WIDTH, 3)
        green.append(_green(rgb))
        assert 100 <= green[-1].sum() <= 300  # the cylinder, whole, upright in the middle of the frame
    rest, bent, back = green
    # at rest the cylinder stands in columns 26-34 from row ~3 to row ~45; the joint sits mid-height
    upper, lower = slice(0, 24), slice(36, HEIGHT)
    swung = rest ^ bent  # pixels that turned green or stopped being green
    assert swung[upper].sum() >= 40
    assert np.nonzero(bent)[0].min() >= np.nonzero(rest)[0].min() + 2  # the bent top sits lower
    assert np.nonzero(bent[upper])[1].mean() >= np.nonzero(rest[upper])[1].mean() + 2  # and off to one side
    assert swung[lower].sum() <= 20  # the lower half, on the first joint, stays (photon noise aside)
    assert (rest ^ back)[upper].sum() <= swung[upper].sum() / 3  # the last frame is the rest pose again
