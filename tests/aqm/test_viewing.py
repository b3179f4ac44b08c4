"""Viewing conditions and the geometry of §6 (docs/08-aqm.md §6)."""
from __future__ import annotations

import numpy as np
import pytest

from pipeline.aqm import DISPLAYS, ViewingConditions, aqm, aqm_geometry, pixels_per_degree
from pipeline.errors import LoomError


def test_pixels_per_degree_is_the_exact_angle_of_a_pixel():
    """0.7 m / 3840 px seen from 0.7 m: 67.0 px/deg (FLIP's default); small-angle form pi d / (180 p)."""
    assert pixels_per_degree(0.7 / 3840, 0.7) == pytest.approx(67.0, abs=0.05)
    assert pixels_per_degree(0.001, 2.0) == pytest.approx(np.pi * 2.0 / (180 * 0.001), rel=1e-6)


def test_named_displays_are_colorvideovdp_models():
    fhd = ViewingConditions.named("standard_fhd")
    assert fhd.display_width_m == pytest.approx(0.5313, abs=1e-4)  # 24-inch 16:9
    assert fhd.ppd == pytest.approx(37.9, abs=0.1)
    assert (fhd.peak_luminance, fhd.black_level) == (200.0, 0.2)
    uhd = ViewingConditions.named("standard_4k", peak_luminance=100.0)
    assert uhd.ppd == pytest.approx(75.4, abs=0.1) and uhd.peak_luminance == 100.0
    assert set(DISPLAYS) == {"standard_fhd", "standard_4k"}
    with pytest.raises(LoomError, match="unknown display"):
        ViewingConditions.named("cinema")


def test_default_is_full_screen_standard_fhd_geometry():
    viewing = ViewingConditions()
    assert viewing.fill == "full_screen"
    assert viewing.ppd == pytest.approx(ViewingConditions.named("standard_fhd").ppd, rel=1e-3)
    # A 320x240 frame fills the 1080-pixel height: 4.5 display pixels a frame pixel.
    assert viewing.frame_scale((240, 320)) == 4.5
    assert viewing.frame_ppd((240, 320)) == pytest.approx(viewing.ppd / 4.5, rel=1e-3)
    assert ViewingConditions(fill="native").frame_ppd((240, 320)) == viewing.ppd
    with pytest.raises(LoomError):
        ViewingConditions(fill="stretched")


@pytest.mark.parametrize("frame", [(240, 320), (1080, 1920), (200, 200)])
def test_aqm_geometry_scales_distance_with_the_image(frame):
    """§6: resampled to 256 with the observer's distance reduced proportionally, so the AQM image's
    pixels per degree are the frame's times the resampling factor, and the visual angle is kept."""
    viewing = ViewingConditions()
    g = aqm_geometry(viewing, frame, 256)
    factor = min(1.0, 256 / max(frame))
    assert g.shape == (round(frame[0] * factor), round(frame[1] * factor))
    assert g.ppd == pytest.approx(viewing.frame_ppd(frame) * factor, rel=1e-2)
    assert g.shape[1] / g.ppd == pytest.approx(frame[1] / viewing.frame_ppd(frame), rel=1e-2)
    assert g.image_area_deg2 == pytest.approx((g.shape[0] / g.ppd) * (g.shape[1] / g.ppd))
    # The scaled distance puts the AQM image, at the display's pixel pitch, at the AQM's ppd.
    pitch = viewing.display_width_m / viewing.resolution[0]
    assert pixels_per_degree(pitch, g.scaled_distance_m) == pytest.approx(g.ppd, rel=1e-9)
    assert "px/deg" in g.describe(viewing)


def test_aqm_reports_the_geometry_ppd(shaded_scene):
    viewing = ViewingConditions.named("standard_4k")
    frame = np.kron(shaded_scene[..., 1], np.ones((2, 2)))  # 512 x 512
    result = aqm(frame, frame, viewing=viewing)
    assert result.ppd == pytest.approx(aqm_geometry(viewing, frame.shape, 256).ppd)
