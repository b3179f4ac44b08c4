"""The RiggedSimple-like and AnimatedMorphCube-like files (tests/scene/deforming_assets.py) rendered end
to end: the frames show the motion where the mesh moves, and only there."""
from __future__ import annotations

import numpy as np

from pipeline.frames.images import frame_paths, read_exr
from pipeline.frames.settings import RenderSettings
from pipeline.run.render import RenderRequest, render
from tests.scene.deforming_assets import animated_morph_cube, rigged_simple

SETTINGS = RenderSettings(width=64, height=48, spp=1)


def _frames(scene_path, out):
    report = render(RenderRequest(scene_path=scene_path, frames="1-3", out_dir=out, settings=SETTINGS, n_photons=3000),
                    scheduler="synchronous")
    assert report["rendered"] == [1, 2, 3]
    rgb = []
    for f in (1, 3):
        channels, _ = read_exr(frame_paths(out, f)[0])
        rgb.append(np.stack([channels[c] for c in "RGB"], axis=-1))
    return rgb


def _centroid(mask):
    rows, cols = np.nonzero(mask)
    return rows.mean(), cols.mean()


def test_rigged_simple_bends_in_the_frames(tmp_path):
    first, last = _frames(rigged_simple(tmp_path / "RiggedSimple-like.glb"), tmp_path / "out")
    # the red cylinder (0.8, 0.2, 0.1) against the grey floor and the black beyond
    red = [(im[..., 0] > 2.5 * im[..., 1]) & (im[..., 0] > 1e-3) for im in (first, last)]
    changed = red[0] ^ red[1]  # pixels that turned red or stopped being red
    # the cylinder stands in columns 29-34 from row 14 (y = 2) to row 37 (y = 0), the pivot at row 26:
    # the upper half leaves the top rows and swings left (-x), bone0's half stands still
    assert red[0][:22].sum() >= 20 and red[1][:22].sum() == 0
    assert np.nonzero(red[1][:30])[1].min() <= np.nonzero(red[0][:30])[1].min() - 6
    assert changed[:28].sum() >= 50
    assert changed[33:38, 26:39].sum() <= 10  # what bleeds red onto the floor varies with the photons


def test_animated_morph_cube_grows_in_the_frames(tmp_path):
    first, last = _frames(animated_morph_cube(tmp_path / "AnimatedMorphCube-like.glb"), tmp_path / "out")
    # the blue cube (0.3, 0.53, 0.8) against the grey floor
    blue = [(im[..., 2] > 1.8 * im[..., 0]) & (im[..., 2] > 1e-3) for im in (first, last)]
    assert blue[1].sum() > 1.4 * blue[0].sum()  # both targets at weight 1: the cube 1.5 x taller and wider
    assert (blue[0] & ~blue[1]).sum() <= 0.05 * blue[0].sum()  # it grows: what was cube stays cube
    rows0, cols0 = np.nonzero(blue[0])
    rows1, cols1 = np.nonzero(blue[1])
    assert rows1.min() <= rows0.min() - 3  # the top rises
    assert cols1.max() >= cols0.max() + 3  # the +X side swells


def test_element_size_option_of_loom_render(tmp_path):
    """AnimatedMorphCube-like (node scaled 100x) renders with its default element size, and
    ``--element-size`` sets it (refusing one too fine in one line, writing nothing)."""
    import json

    from click.testing import CliRunner

    from pipeline.cli import main

    scene = animated_morph_cube(tmp_path / "cube.glb")
    common = ["render", str(scene), "--frames", "1-2", "--photons", "2000", "--resolution", "16x12", "--spp", "1",
              "--scheduler", "synchronous", "--quiet"]
    ok = CliRunner().invoke(main, [*common, "--out", str(tmp_path / "o"), "--element-size", "0.25"])
    assert ok.exit_code == 0, ok.output
    assert json.loads((tmp_path / "o" / "report.json").read_text())["settings"]["job"]["element_size"] == 0.25
    fine = CliRunner().invoke(main, [*common, "--out", str(tmp_path / "f"), "--element-size", "1e-5"])
    assert fine.exit_code == 2 and len(fine.output.strip().splitlines()) == 1
    assert f"{scene}: element_size: element_size 1e-05 gives" in fine.output and "--element-size" in fine.output
    assert not (tmp_path / "f").exists()
