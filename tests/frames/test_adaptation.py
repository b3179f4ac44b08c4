"""Eye adaptation from what the camera sees, over the eye's time course (pipeline/frames/tonemap.py,
pipeline/frames/camera_paths.py visible_adaptation), end to end on real renders of a BoxAnimated-like scene."""
from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest

from pipeline.frames.images import frame_paths, read_exr
from pipeline.frames.settings import RenderSettings
from pipeline.frames.tonemap import ToneMapping, adapt_in_time, image_adaptation
from pipeline.run.render import RenderRequest, render
from pipeline.segments.records import read_record
from tests.frames.adaptation_scenes import FPS, box_scene

FRAMES = 24
SETTINGS = RenderSettings(width=64, height=48, spp=1)


def _render(tmp, photons: int, **scene):
    out = tmp / "out"
    render(RenderRequest(scene_path=box_scene(tmp / "box.glb", frames=FRAMES, **scene), frames=f"1-{FRAMES}",
                         out_dir=out, settings=SETTINGS, n_photons=photons), scheduler="synchronous")
    return out


def _png(out, f) -> np.ndarray:
    return oiio.ImageBuf(str(frame_paths(out, f)[1])).get_pixels(oiio.UINT8).astype(float)


def _background(png: np.ndarray) -> float:
    """Mean of the ground nearest the camera: the box, its shadow (cast away from the camera) and
    its colour bleeding never reach it."""
    return float(png[int(png.shape[0] * 0.85):].mean())


def _raw_and_adapted(out) -> tuple[np.ndarray, np.ndarray]:
    rec = read_record(out, 0)
    raw = np.array([rec.frames[str(f)]["adaptation"] for f in range(1, FRAMES + 1)])
    adapted = np.array([float(read_exr(frame_paths(out, f)[0])[1]["adaptation"]) for f in range(1, FRAMES + 1)])
    return raw, adapted


@pytest.fixture(scope="module")
def sliding(tmp_path_factory):
    """The box slides under an unchanged light; few photons, so the maps are noisy."""
    return _render(tmp_path_factory.mktemp("sliding"), 1000)


@pytest.fixture(scope="module")
def switched(tmp_path_factory):
    """A second, ten times stronger light comes on at frame 8."""
    return _render(tmp_path_factory.mktemp("switched"), 4000, switch_at=8)


def test_unchanged_lights_hold_the_background_within_one_level(sliding):
    # With every element in the frustum, occluded faces and photon-estimated direct light
    # included, the same background varied by 1.98 levels here
    band = [_background(_png(sliding, f)) for f in range(1, FRAMES + 1)]
    assert max(band) - min(band) <= 1.0, band


def test_the_blue_box_keeps_its_hue(sliding):
    r, g, b = _png(sliding, FRAMES // 2)[int(48 * 0.45), 32]  # the box's front face at mid-animation
    # base colour (0.30, 0.53, 0.80) is sRGB (149, 192, 231): saturation 0.35; frustum-wide
    # adaptation gave (180, 211, 227), saturation 0.21, nearly white
    assert b > r + 50 and g > r and (b - r) / b > 0.28, (r, g, b)


def test_each_frame_adapts_to_what_it_sees_and_never_to_what_comes_later(sliding):
    raw, adapted = _raw_and_adapted(sliding)
    times = np.arange(FRAMES) / FPS
    np.testing.assert_allclose(adapted, adapt_in_time(raw, times, ToneMapping()), rtol=1e-6)  # EXR metadata: float32
    assert np.array_equal(adapt_in_time(raw[:10], times[:10]), adapt_in_time(raw, times)[:10])


def test_a_light_switched_on_brightens_the_view_then_the_eye_adapts(switched):
    raw, adapted = _raw_and_adapted(switched)
    on = 7  # index of frame 8
    assert raw[on:].min() > 5 * raw[:on].max()  # the frame's own L_wa steps at once
    assert np.all(np.diff(adapted[on - 1:on + 11]) > 0)  # the eye's adaptation follows, monotone
    assert adapted[on] < 0.5 * raw[on]  # not at once: the first frame lit is seen by an eye adapted to the dark
    assert abs(adapted[-1] / raw[-1] - 1) < 0.02  # settled within a second
    band = np.array([_background(_png(switched, f)) for f in range(1, FRAMES + 1)])
    assert band[on] > band[on - 1] + 20  # the switch brightens the view ...
    assert np.all(np.diff(band[on:on + 10]) < 0)  # ... then the exposure settles, monotone


def test_adaptation_leaves_out_pixels_that_see_nothing():
    rgb = np.zeros((2, 2, 3))
    rgb[0] = 0.5
    seen = np.array([[True, True], [False, False]])
    assert image_adaptation(rgb, seen) == pytest.approx(0.5, rel=1e-3)
    assert image_adaptation(rgb, np.ones((2, 2), bool)) < 0.05  # the empty half would drag it down
