"""Each stage against the published numbers it implements (docs/08-aqm.md; Daly 1993, Kelly 1979, Daly 1998)."""
from __future__ import annotations

import numpy as np
import pytest
from aqm_data import SIZE, grating, threshold_contrast

from pipeline.aqm import ViewingConditions
from pipeline.aqm.bands import band_filters, channel_filters, dom_filters, radial_frequency
from pipeline.aqm.csf import daly_csf, kelly_daly_csf, retinal_velocity, velocity_factor
from pipeline.aqm.display import display_luminance, relative_luminance, resample
from pipeline.aqm.nonlinearity import daly_response, nonlinear_contrast

RHO = np.linspace(0.05, 30.0, 6000)


@pytest.mark.parametrize("lum,peak,at", [(100.0, 237, 3.2), (10.0, 181, 2.5), (1.0, 117, 1.8)])
def test_daly_csf_peaks(lum, peak, at):
    """Peak sensitivity falls and moves to lower frequencies as the adaptation luminance drops."""
    s = daly_csf(RHO, lum, i2=(256 / 30) ** 2, distance_m=0.5)
    assert s.max() == pytest.approx(peak, rel=0.01)
    assert RHO[s.argmax()] == pytest.approx(at, abs=0.1)


def test_daly_csf_oblique_effect():
    """Diagonal gratings are harder to see than horizontal or vertical ones at high frequency."""
    kw = {"i2": 16.0, "distance_m": 0.6}
    assert daly_csf(16.0, 100.0, theta=np.pi / 4, **kw) < daly_csf(16.0, 100.0, theta=0.0, **kw)


@pytest.mark.parametrize("velocity,peak,at", [(0.15, 245, 4.8), (1.0, 251, 3.0), (4.0, 184, 1.2), (16.0, 130, 0.37)])
def test_spatiovelocity_csf_peaks(velocity, peak, at):
    """Kelly/Daly: faster retinal motion moves peak sensitivity to lower spatial frequencies."""
    s = kelly_daly_csf(RHO, velocity)
    assert s.max() == pytest.approx(peak, rel=0.01)
    assert RHO[s.argmax()] == pytest.approx(at, rel=0.05)


def test_velocity_removes_high_frequencies_first():
    factors = velocity_factor(np.array([1.0, 4.0, 16.0]), 10.0)
    assert factors[0] > factors[1] > factors[2]
    assert np.all(velocity_factor(RHO, 0.15) == 1.0)


@pytest.mark.parametrize("gain,expected", [(0.0, 9.85), (0.82, 1.65), (1.0, 0.15)])
def test_retinal_velocity_of_smooth_pursuit(gain, expected):
    """Daly 1998: v_R = |v_I - min(g v_I + 0.15, 80)|, never below the 0.15 deg/s drift."""
    assert retinal_velocity(np.array([10.0]), gain)[0] == pytest.approx(expected)


def test_saccade_limit_caps_pursuit():
    assert retinal_velocity(np.array([200.0]), 1.0)[0] == pytest.approx(80.0)


def test_ppd_of_reference_display():
    """0.7 m wide 3840 px display viewed from 0.7 m: 67.0 px/deg (FLIP's default)."""
    assert ViewingConditions(display_width_m=0.7, resolution=(3840, 2160), viewing_distance_m=0.7).ppd == \
        pytest.approx(67.0, abs=0.05)
    assert ViewingConditions.for_ppd(40.0).ppd == pytest.approx(40.0)


def test_display_luminance_spans_black_to_peak():
    viewing = ViewingConditions(peak_luminance=200.0, black_level=0.5)
    y = relative_luminance(np.array([[[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [4.0, 4.0, 4.0]]]))
    np.testing.assert_allclose(display_luminance(y, viewing), [[0.5, 200.0, 200.0]])


def test_nonlinearity_is_weber_contrast_near_adaptation_and_compressive_above():
    adaptation = np.array([100.0])
    small = nonlinear_contrast(np.array([101.0]), adaptation)
    assert small[0] == pytest.approx(0.01, rel=0.01)
    big = nonlinear_contrast(np.array([1000.0]), adaptation)
    assert big[0] < 9.0  # Weber contrast would be 9
    response = daly_response(np.array([1.0, 10.0, 100.0, 1000.0]), adaptation)
    assert np.all(np.diff(response) > 0) and response[-1] < 1


def test_bands_partition_sums_to_one():
    rho = radial_frequency((SIZE, SIZE))
    dom = dom_filters(rho)
    inside = rho < 0.5
    np.testing.assert_allclose(dom.sum(axis=0)[inside], 1.0, atol=1e-12)
    np.testing.assert_allclose(band_filters((SIZE, SIZE)).sum(axis=0)[inside], 1.0, atol=1e-12)


def test_cortex_channels_partition_sums_to_one():
    """Daly's 5 x 6 oriented channels and the base band add up to 1 at every frequency and orientation."""
    filters, band = channel_filters((SIZE, SIZE))
    assert filters.shape[0] == 31 and list(np.bincount(band)) == [6, 6, 6, 6, 6, 1]
    inside = radial_frequency((SIZE, SIZE)) < 0.5
    np.testing.assert_allclose(filters.sum(axis=0)[inside], 1.0, atol=1e-12)


def test_single_precision_bands_and_channels_match_double_precision():
    """The decompositions run in float32 (bands.py): against float64 transforms of the same
    spectrum, every band and channel image within 1e-5 of the image's largest value."""
    from pipeline.aqm.bands import decompose, decompose_channels

    rng = np.random.default_rng(4)
    image = rng.normal(0.0, 1.0, (SIZE, SIZE)) + 5.0 * grating(8)
    spectrum = np.fft.rfft2(image)
    channels, band = decompose_channels(spectrum, (SIZE, SIZE))
    bands = decompose(spectrum, (SIZE, SIZE))
    assert channels.dtype == bands.dtype == np.float32
    filters, band64 = channel_filters((SIZE, SIZE))
    for got, h in ((channels, filters), (bands, band_filters((SIZE, SIZE)))):
        exact = np.fft.irfft2(spectrum[None] * h, s=(SIZE, SIZE))
        assert np.abs(got - exact).max() < 1e-5 * np.abs(exact).max()
    assert np.array_equal(band, band64)


def test_resampling_keeps_visual_angle(grating_viewing):
    """A frame twice as large seen with twice the ppd has the same grating threshold after resampling (§6)."""
    big = ViewingConditions.for_ppd(2 * grating_viewing.ppd)
    from pipeline.aqm import aqm_luminance

    pattern = np.kron(grating(4), np.ones((2, 2)))
    contrast = threshold_contrast(4, 100.0, grating_viewing)
    field = np.full(pattern.shape, 100.0)
    centre = slice(SIZE // 4, -SIZE // 4)
    result = aqm_luminance(field, 100 * (1 + 1.05 * contrast * pattern), viewing=big)
    assert result.map.shape == (SIZE, SIZE) and result.ppd == pytest.approx(grating_viewing.ppd)
    assert result.map[centre, centre].max() > 0.75
    result = aqm_luminance(field, 100 * (1 + 0.95 * contrast * pattern), viewing=big)
    assert result.map[centre, centre].max() < 0.75


def test_resample_keeps_mean_and_aspect():
    rng = np.random.default_rng(3)
    image = rng.random((480, 640))
    small = resample(image, (192, 256))
    assert small.mean() == pytest.approx(image.mean())
