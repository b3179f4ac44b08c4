"""A camera-less, light-less animated two-box file renders with the defaults (``loom render``,
synchronous scheduler, real files) and its animation is visible: the moving box's pixels are
where the auto camera projects it, frame by frame, lit by the default sun and sky."""
from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from pipeline.cli import main
from pipeline.frames.images import frame_paths, read_exr
from pipeline.scene import read_scene
from tests.scene.unlit_scenes import FRAMES, INNER, SLIDE, box_in_box

W, H = 64, 48


def _layer(channels, name):
    return np.stack([channels[f"{name}.{c}" if name else c] for c in "RGB"], axis=-1)


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("unlit")
    path = box_in_box(tmp / "bib.glb")
    result = CliRunner().invoke(main, ["render", str(path), "--out", str(tmp / "out"), "--resolution", f"{W}x{H}",
                                       "--spp", "2", "--photons", "4000", "--fmax", "2", "--scheduler",
                                       "synchronous", "--quiet"])
    assert result.exit_code == 0, result.output
    return path, tmp / "out"


def _projected_centre(scene, frame):
    """Pixel (x, y) of the inner box's centre through the auto camera (kernels/camera.py's mapping)."""
    cam = scene.pose_frame(frame).camera
    world = scene.world_matrices(scene.timeline.time(frame))
    centre = world[scene.nodes.index(next(n for n in scene.nodes if n.name == "inner_box"))] @ [0, 0.3, 0, 1]
    x, y, z = (cam.world_to_camera @ centre)[:3]
    tan_y = np.tan(cam.definition.yfov / 2)
    return ((x / -z) / (tan_y * W / H) + 1) * W / 2, (1 - (y / -z) / tan_y) * H / 2


def test_every_frame_is_rendered_with_the_default_camera_and_lights(rendered):
    path, out = rendered
    for f in range(1, FRAMES + 1):
        exr, png = frame_paths(out, f)
        assert exr.is_file() and png.is_file()
    channels, meta = read_exr(frame_paths(out, 1)[0])
    beauty, alpha = _layer(channels, ""), channels["A"]
    assert 0.2 < alpha.mean() < 0.9  # the boxes fill the frame, the sky shows round them
    sky = read_scene(path).sky
    np.testing.assert_allclose(_layer(channels, "direct")[alpha == 0], np.broadcast_to(
        np.float32(sky.ground), ((alpha == 0).sum(), 3)), rtol=1e-3)  # the ground half below the horizon
    assert beauty[alpha == 1].mean() > 0.1  # lit


def test_the_moving_box_is_where_the_camera_sees_it_in_every_frame(rendered):
    path, out = rendered
    scene = read_scene(path)
    centres = []
    for f in (1, FRAMES // 2, FRAMES):
        channels, _ = read_exr(frame_paths(out, f)[0])
        albedo = _layer(channels, "albedo")
        red = np.all(np.abs(albedo - np.float32(INNER)) < 0.05, axis=-1)
        assert red.sum() > 20
        ys, xs = np.nonzero(red)
        centre = np.array([xs.mean() + 0.5, ys.mean() + 0.5])
        np.testing.assert_allclose(centre, _projected_centre(scene, f), atol=1.5)
        direct = _layer(channels, "direct")[red]
        assert direct.mean() > 0.02  # the box is lit by the sun or the sky
        centres.append(centre)
    shift = centres[-1][0] - centres[0][0]
    assert shift > 0.15 * W * SLIDE / 3.0  # it slides to the right, a visible distance
    first, last = (read_exr(frame_paths(out, f)[0])[0] for f in (1, FRAMES))
    assert np.abs(_layer(first, "") - _layer(last, "")).mean() > 0.005
