"""Pixel flow from camera motion by 3-D warping (§6): image velocity in deg/s."""
from __future__ import annotations

import numpy as np
import pytest
from aqm_data import SIZE, monte_carlo

from pipeline.aqm import Motion, ViewingConditions, aqm, image_velocity
from pipeline.aqm.flow import focal_pixels, warp_displacement
from pipeline.errors import LoomError
from pipeline.frames.perceived import camera_flow, viewing_for
from pipeline.frames.tonemap import ToneMapping
from pipeline.scene import read_scene
from tests.conftest import basic_builder

YFOV = np.radians(45.0)
SHAPE = (48, 64)


def translation(x=0.0, y=0.0, z=0.0) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def yaw(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    m = np.eye(4)
    m[0, 0], m[0, 2], m[2, 0], m[2, 2] = c, s, -s, c
    return m


@pytest.fixture
def wall():
    return np.full(SHAPE, 4.0)


def test_still_camera_gives_no_flow(wall):
    v = image_velocity(wall, np.eye(4), yfov=YFOV, fps=25, ppd=30, previous=np.eye(4), following=np.eye(4))
    np.testing.assert_allclose(v, 0.0, atol=1e-9)


@pytest.mark.parametrize("depth", [2.0, 8.0])
def test_sideways_camera_motion_moves_pixels_by_parallax(depth):
    """Camera moving right by t: points at depth z slide left by f t / z pixels (nearer is faster)."""
    step = 0.1
    moved = translation(x=-step)  # world-to-camera of a camera at x = +step
    d = warp_displacement(np.full(SHAPE, depth), np.eye(4), moved, YFOV)
    np.testing.assert_allclose(d[..., 0], -focal_pixels(SHAPE[0], YFOV) * step / depth, rtol=1e-9)
    np.testing.assert_allclose(d[..., 1], 0.0, atol=1e-9)


def test_velocity_in_degrees_per_second(wall):
    step, fps, ppd = 0.1, 24.0, 30.0
    v = image_velocity(wall, np.eye(4), yfov=YFOV, fps=fps, ppd=ppd, previous=translation(x=step),
                       following=translation(x=-step))
    expected = -focal_pixels(SHAPE[0], YFOV) * step / 4.0 * fps / ppd
    np.testing.assert_allclose(v[..., 0], expected, rtol=1e-9)


def test_a_zoom_moves_pixels_away_from_the_centre_by_the_focal_ratio(wall):
    """A still camera zooming in: every point keeps its direction, so a pixel at (u, v) from the
    image centre moves to (u, v) f1 / f0, at any depth."""
    wider, narrower = YFOV, np.radians(40.0)
    d = warp_displacement(wall, np.eye(4), np.eye(4), wider, narrower)
    scale = focal_pixels(SHAPE[0], narrower) / focal_pixels(SHAPE[0], wider) - 1.0
    u = np.arange(SHAPE[1]) + 0.5 - SHAPE[1] / 2
    v = np.arange(SHAPE[0]) + 0.5 - SHAPE[0] / 2
    np.testing.assert_allclose(d[..., 0], scale * u[None, :] * np.ones(SHAPE), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(d[..., 1], scale * v[:, None] * np.ones(SHAPE), rtol=1e-9, atol=1e-12)
    fps, ppd = 30.0, 30.0  # the central difference of a steady zoom: the mean of both steps
    vel = image_velocity(wall, np.eye(4), yfov=wider, fps=fps, ppd=ppd, previous=(np.eye(4), np.radians(50.0)),
                         following=(np.eye(4), narrower))
    back = warp_displacement(wall, np.eye(4), np.eye(4), wider, np.radians(50.0))
    np.testing.assert_allclose(vel, (d - back) / 2 * fps / ppd, rtol=1e-9, atol=1e-12)


def test_translation_leaves_points_at_infinity_still():
    sky = np.full(SHAPE, np.inf)
    d = warp_displacement(sky, np.eye(4), translation(x=-1.0, z=2.0), YFOV)
    np.testing.assert_allclose(d, 0.0, atol=1e-9)


def test_pan_moves_every_depth_alike():
    """A camera pan (rotation) gives the same flow at any depth; at the centre f tan(angle) pixels."""
    angle = np.radians(1.0)
    near = warp_displacement(np.full(SHAPE, 1.0), np.eye(4), yaw(angle), YFOV)
    sky = warp_displacement(np.full(SHAPE, np.inf), np.eye(4), yaw(angle), YFOV)
    np.testing.assert_allclose(near, sky, atol=1e-9)
    centre = near[SHAPE[0] // 2, SHAPE[1] // 2, 0]
    assert abs(centre) == pytest.approx(focal_pixels(SHAPE[0], YFOV) * np.tan(angle), rel=0.01)


def test_point_behind_next_camera_uses_previous(wall):
    """A camera passing the wall: pixels behind it take the other neighbour's motion."""
    v = image_velocity(wall, np.eye(4), yfov=YFOV, fps=25, ppd=30, previous=translation(x=0.1),
                       following=translation(z=10.0))
    assert np.all(np.isfinite(v))
    one_sided = image_velocity(wall, np.eye(4), yfov=YFOV, fps=25, ppd=30, previous=translation(x=0.1))
    np.testing.assert_allclose(v, one_sided)


@pytest.mark.parametrize("depth", [np.full(SHAPE, -1.0), np.full(SHAPE, np.nan), np.zeros(SHAPE)])
def test_bad_depth_is_one_line_error(depth):
    with pytest.raises(LoomError) as err:
        image_velocity(depth, np.eye(4), yfov=YFOV, fps=25, ppd=30, following=np.eye(4))
    assert "\n" not in str(err.value) and "depth" in str(err.value)


def test_flow_needs_a_neighbour(wall):
    with pytest.raises(LoomError):
        image_velocity(wall, np.eye(4), yfov=YFOV, fps=25, ppd=30)


def test_camera_flow_lowers_d_aqm_of_untracked_noise(shaded_scene):
    """Noise on a floor sliding past a moving camera is less visible than on a still frame (§6)."""
    viewing = ViewingConditions()
    depth = np.broadcast_to(np.linspace(10.0, 2.0, SIZE)[:, None], (SIZE, SIZE))
    flow = image_velocity(depth, np.eye(4), yfov=YFOV, fps=25, ppd=viewing.ppd, previous=translation(x=0.05),
                          following=translation(x=-0.05))
    a, b = monte_carlo(shaded_scene, 800, 1), monte_carlo(shaded_scene, 800, 2)
    still = aqm(a, b, viewing=viewing).d_aqm
    moving = aqm(a, b, motion=Motion(flow, pursuit_gain=0.0), viewing=viewing).d_aqm
    assert 0 < moving < still


def test_a_rendered_zoom_flows_as_its_closed_form(tmp_path):
    """A still camera 1.5 above the floor looking straight down, zooming 0.8 -> 0.4 rad over 1 s by a
    KHR_animation_pointer channel: the AQM's flow of frame 16 (pipeline/frames/perceived.py, from a
    depth image cast with Embree) is the central difference of the pure zoom's closed form, at every
    pixel, whatever its depth."""
    b = basic_builder()
    cam = b.add_camera("down", 0.8, 0.1)
    b.add_node("cam", camera=cam, translation=(1, 1.5, 1), rotation=(-np.sqrt(0.5), 0, 0, np.sqrt(0.5)))
    b.add_pointer_animation("zoom", f"/cameras/{cam}/perspective/yfov", [0, 1], [0.8, 0.4])
    scene = read_scene(b.write(tmp_path / "zoom.glb"))
    h, w = 48, 64
    flow = camera_flow(scene, 16, w, h)
    fov = {f: scene.pose_frame(f).camera.definition.yfov for f in (15, 16, 17)}
    ratio = {f: focal_pixels(h, fov[f]) / focal_pixels(h, fov[16]) - 1.0 for f in (15, 17)}
    u = np.arange(w) + 0.5 - w / 2
    v = np.arange(h) + 0.5 - h / 2
    scale = (ratio[17] - ratio[15]) / 2 * scene.timeline.fps / viewing_for(ToneMapping()).frame_ppd((h, w))
    np.testing.assert_allclose(flow[..., 0], scale * u[None, :] * np.ones((h, w)), rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(flow[..., 1], scale * v[:, None] * np.ones((h, w)), rtol=1e-6, atol=1e-9)
    assert scale > 0  # zooming in: pixels move away from the centre
