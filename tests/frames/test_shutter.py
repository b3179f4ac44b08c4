"""Motion blur (pipeline/frames/shutter.py, camera_paths.render_exposure) against closed forms: the
instants of a pixel's samples; a 1 m emitter (8 pixels) moving 1 m a frame before an orthographic
camera smears into the box filter of its motion while the shutter is open, its light conserved;
a camera sliding past a still emitter smears it alike; nothing moving renders the instant to the
bit; `loom render --shutter` renders it and refuses a shutter outside [0, 1] in one line."""
from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from pygltflib import Camera, Orthographic

from pipeline.cli import main
from pipeline.frames.camera_paths import CameraPaths, render_exposure, render_frame
from pipeline.frames.images import frame_paths, read_exr
from pipeline.frames.shutter import shutter_offsets, shutter_states
from pipeline.scene import read_scene
from pipeline.scene.builtin.gltf_builder import GltfBuilder

SQUARE = np.array([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]], float)  # facing +z
SQUARE_FACES = np.array([[0, 1, 2], [0, 2, 3]])
W, H, SPP = 64, 32, 8  # an orthographic view 8 m x 4 m: 8 pixels a metre


def emitter_scene(path, *, moving="emitter"):
    """A 1 m emitter of radiance 1 seen face-on by an orthographic camera at z = 5; ``moving``
    (the emitter or the camera) goes 1 m a frame along +x, so that at frame 3 it is centred."""
    b = GltfBuilder()
    glow = b.add_material("glow", (0.0, 0.0, 0.0), emissive=(1.0, 1.0, 1.0))
    node = b.add_node("square", b.add_mesh("square", SQUARE, SQUARE_FACES, material=glow))
    b.gltf.cameras.append(Camera(name="front", type="orthographic",
                                 orthographic=Orthographic(xmag=4.0, ymag=2.0, znear=0.0, zfar=10.0)))
    cam = b.add_node("front_view", camera=0, translation=(0, 0, 5))
    if moving == "emitter":
        b.add_animation("move", node, "translation", [0, 1], [[-2, 0, 0], [28, 0, 0]])
    elif moving == "camera":
        b.add_animation("move", cam, "translation", [0, 1], [[2, 0, 5], [-28, 0, 5]])
    else:
        b.add_animation("still", node, "translation", [0, 1], [[0, 0, 0], [0, 0, 0]])
    return b.write(path)


def _direct(scene, shutter: float) -> np.ndarray:
    state = scene.pose_frame(3)
    paths = CameraPaths(W, H, SPP, 0, 3, 0, 1)
    blur = shutter_states(scene, 3, shutter, SPP)
    img = render_frame(state, None, None, paths) if blur is None else render_exposure(state, blur, None, None, paths)
    return img.direct[..., 0]


def _box_profile(shutter: float) -> np.ndarray:
    """Each column's expected share of the emitter's radiance: over the pixel's width and the
    samples' instants, the 8-pixel box shifted by offset x 8 pixels (1 m a frame)."""
    x = (np.arange(W * 64) + 0.5) / 64 - W / 2  # sub-pixel positions from the image's centre
    cover = np.mean([np.abs(x - 8 * dt) < 4 for dt in shutter_offsets(shutter, SPP)], axis=0)
    return cover.reshape(W, 64).mean(axis=1)


def test_the_samples_instants_are_the_strata_centres():
    np.testing.assert_allclose(shutter_offsets(0.5, 4), [-0.1875, -0.0625, 0.0625, 0.1875])
    assert not shutter_offsets(0.0, 8).any()
    with pytest.raises(ValueError, match="shutter must be in"):
        shutter_offsets(1.5, 8)


@pytest.mark.parametrize("moving", ["emitter", "camera"])
def test_a_moving_emitter_smears_into_the_box_of_its_motion(tmp_path, moving):
    scene = read_scene(emitter_scene(tmp_path / "e.glb", moving=moving))
    sharp, blurred = _direct(scene, 0.0), _direct(scene, 1.0)
    rows = slice(12, 20)  # the emitter's 8 rows, whole pixels
    assert sharp[rows].sum() == pytest.approx(64, abs=0.01)  # 8 x 8 pixels of radiance 1, edges on pixel edges
    np.testing.assert_allclose(sharp[rows].mean(axis=0), _box_profile(0.0), atol=1e-6)
    profile = blurred[rows].mean(axis=0)
    assert (profile > 0).sum() == 16 and (sharp[rows].mean(axis=0) > 0).sum() == 8
    np.testing.assert_allclose(profile, _box_profile(1.0), atol=0.1)  # one sample an instant: 1/8 steps
    assert blurred[rows].sum() == pytest.approx(64, rel=0.03)  # the light is spread, not lost
    assert blurred[:12].max() == 0 and blurred[20:].max() == 0  # motion along x only


def test_nothing_moving_renders_the_instant_to_the_bit(tmp_path):
    scene = read_scene(emitter_scene(tmp_path / "still.glb", moving=None))
    np.testing.assert_array_equal(_direct(scene, 1.0), _direct(scene, 0.0))


def test_loom_render_blurs_with_a_shutter_and_refuses_one_outside_0_1(tmp_path):
    path = emitter_scene(tmp_path / "e.glb")
    common = ["render", str(path), "--frames", "3", "--photons", "1000", "--temporal", "off", "--resolution",
              f"{W}x{H}", "--scheduler", "synchronous", "--quiet"]
    lit = []
    for shutter in ("0", "0.5"):
        out = tmp_path / f"s{shutter}"
        result = CliRunner().invoke(main, [*common, "--out", str(out), "--shutter", shutter])
        assert result.exit_code == 0, result.output
        direct = read_exr(frame_paths(out, 3)[0])[0]["direct.R"]
        lit.append(int((direct[12:20].mean(axis=0) > 0).sum()))
    assert lit == [8, 12]  # 8 pixels, and 4 more for half a frame's motion (0.5 m)
    bad = CliRunner().invoke(main, [*common, "--out", str(tmp_path / "bad"), "--shutter", "1.5"])
    assert bad.exit_code == 2 and "shutter must be a number in [0, 1], got 1.5" in bad.output
    assert len(bad.output.strip().splitlines()) == 1 and not (tmp_path / "bad").exists()
