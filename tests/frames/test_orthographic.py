"""Orthographic cameras (glTF ``orthographic``: parallel rays through a view ``2 ymag`` high, the
width by the output's aspect): chosen by name, rendered against the closed form of a floor's
footprint (2 m of a 4 m high view cover half the rows), the AQM's warping of a sliding view (every
pixel moves by the slide over the pixel size, whatever its depth; the sky not at all), a zoom of
ymag through KHR_animation_pointer; bad magnifications are one-line errors."""
from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from pygltflib import Camera, Orthographic

from pipeline.aqm.flow import Ortho, warp_displacement
from pipeline.cli import main
from pipeline.errors import SceneError
from pipeline.frames.images import frame_paths, read_exr
from pipeline.scene import read_scene
from pipeline.scene.builtin.gltf_builder import GltfBuilder
from tests.conftest import QUAD, QUAD_FACES

DOWN = (-0.7071068, 0, 0, 0.7071068)  # -Z turned to -Y


def top_view(path, *, ymag=2.0, xmag=2.0, slide=False, zoom=None):
    """The 2 x 2 floor (x, z in [0, 2]) under a sun straight above, seen from (1, 5, 1) straight
    down by an orthographic camera ``top`` (ymag 2: a view 4 m high); ``slide`` moves it 1 m in x
    over frames 1-3 (30 fps), ``zoom`` keys its ymag."""
    b = GltfBuilder()
    b.add_node("floor", b.add_mesh("floor", QUAD, QUAD_FACES, material=b.add_material("grey", (0.5, 0.5, 0.5))))
    b.add_node("sun", light=b.add_directional_light("sun", (1, 1, 1), 3.0), rotation=DOWN)
    b.gltf.cameras.append(Camera(name="top", type="orthographic",
                                 orthographic=Orthographic(xmag=xmag, ymag=ymag, znear=0.0, zfar=10.0)))
    cam = b.add_node("top_view", camera=len(b.gltf.cameras) - 1, translation=(1, 5, 1), rotation=DOWN)
    if slide:
        b.add_animation("slide", cam, "translation", [0, 2 / 30], [[1, 5, 1], [2, 5, 1]])
    if zoom is not None:
        b.add_pointer_animation("zoom", "/cameras/0/orthographic/ymag", [0, 2 / 30], zoom)
    return b.write(path)


def test_an_orthographic_camera_is_chosen_and_described(tmp_path):
    scene = read_scene(top_view(tmp_path / "top.glb"), camera="top")
    cam = scene.pose(0).camera
    assert cam.definition.orthographic and cam.definition.ymag == 2.0
    info = CliRunner().invoke(main, ["info", str(tmp_path / "top.glb")]).output
    assert "rendering with top_view" in info
    assert not any(line.startswith("ignored") for line in info.splitlines())  # nothing left out


def test_the_floor_covers_its_closed_form_footprint(tmp_path):
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["render", str(top_view(tmp_path / "top.glb")), "--out", str(out), "--frames",
                                       "1", "--photons", "2000", "--temporal", "off", "--resolution", "32x24",
                                       "--spp", "1", "--scheduler", "synchronous", "--quiet"])
    assert result.exit_code == 0, result.output
    direct = read_exr(frame_paths(out, 1)[0])[0]["direct.R"]
    # 24 rows span 4 m and 32 columns 5.33 m: the floor's 2 m are rows 6-17 and columns 10-21
    lit = direct > 0
    assert lit[7:17, 11:21].all() and not lit[:5].any() and not lit[19:].any()
    assert not lit[:, :9].any() and not lit[:, 23:].any() and 132 <= lit.sum() <= 156
    inner = direct[7:17, 11:21]
    assert inner.max() / inner.min() < 1.001  # parallel rays and a sun: one irradiance everywhere


def test_a_sliding_view_moves_every_pixel_alike():
    rng = np.random.default_rng(3)
    depth = rng.uniform(1, 9, (24, 32))
    depth[:4] = np.inf  # sky
    here = np.eye(4)
    there = np.eye(4)
    there[0, 3] = -0.5  # the camera 0.5 m to the right: the world moves left in its view
    shift = warp_displacement(depth, here, there, Ortho(2.0))
    np.testing.assert_allclose(shift[4:, :, 0], -0.5 * 12 / 2.0)  # 0.5 m over 2 / 12 m a pixel
    np.testing.assert_allclose(shift[4:, :, 1], 0.0, atol=1e-12)
    assert not shift[:4].any()  # every pixel of the sky sees the same sky


def test_a_sliding_and_zooming_orthographic_camera_renders_with_the_guided_defaults(tmp_path):
    path = top_view(tmp_path / "slide.glb", slide=True, zoom=[[2.0], [1.5]])
    scene = read_scene(path)
    assert scene.pose(2 / 30).camera.definition.ymag == pytest.approx(1.5) and scene.has_camera_motion
    result = CliRunner().invoke(main, ["render", str(path), "--out", str(tmp_path / "out"), "--resolution", "32x24",
                                       "--spp", "1", "--scheduler", "synchronous", "--quiet"])
    assert result.exit_code == 0, result.output
    assert read_exr(frame_paths(tmp_path / "out", 3)[0])[0]["direct.R"].max() > 0


def test_a_zero_magnification_is_a_one_line_error(tmp_path):
    with pytest.raises(SceneError, match=r"cameras\[0\].orthographic: xmag 2.0 and ymag 0.0 must be finite and "
                                         r"not zero"):
        read_scene(top_view(tmp_path / "flat.glb", ymag=0.0))
