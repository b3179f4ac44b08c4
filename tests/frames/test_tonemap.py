"""Tone mapping (Ward 1994) and the eye's time course (Krawczyk et al. 2005, Durand & Dorsey 2000): closed forms."""
from __future__ import annotations

import numpy as np
import pytest

from pipeline.errors import LoomError
from pipeline.frames.tonemap import (
    KEY,
    ToneMapping,
    aces_filmic,
    adapt_in_time,
    display_linear,
    log_average,
    rod_sensitivity,
    srgb_encode,
    tonemap,
    ward_scale,
)


def test_ward_scale_closed_form():
    assert ward_scale(50.0, 100.0) == pytest.approx(1.0)  # adapted to half the display's white
    la = 0.3
    assert ward_scale(la) == pytest.approx(((1.219 + 50 ** 0.4) / (1.219 + la ** 0.4)) ** 2.5)
    assert ward_scale(0.01) > ward_scale(1.0) > ward_scale(100.0)  # dimmer worlds are scaled up


def test_log_average_is_geometric_mean_and_survives_zeros():
    assert log_average(np.array([1.0, 100.0]) - 1e-4) == pytest.approx(10.0)
    assert np.isfinite(log_average(np.zeros(5))) and log_average(np.zeros(0)) > 0


def test_adaptation_follows_a_step_exponentially_with_the_cone_and_rod_time_constants():
    t = np.arange(8) / 24.0
    values = np.array([1.0, 1.0, 100.0, 100.0, 100.0, 100.0, 100.0, 100.0])
    params = ToneMapping()
    s = adapt_in_time(values, t, params)
    sigma = rod_sensitivity(1.0)  # 0.04 / 1.04: at 1 cd/m^2 the cones adapt
    tau = sigma * 0.4 + (1 - sigma) * 0.1
    assert s[1] == 1.0 and s[2] == pytest.approx(1.0 + 99.0 * (1 - np.exp(-(1 / 24) / tau)))
    assert np.all(np.diff(s[1:]) > 0) and s[-1] < 100.0  # no jump, a monotone approach to the new level
    # in the dark the rods' slower constant dominates: a step from 0.001 cd/m^2 moves less in one frame
    dark = adapt_in_time([0.001, 0.1], t[:2], params)
    assert (dark[1] - 0.001) / 0.099 < (s[2] - 1.0) / 99.0
    np.testing.assert_allclose(adapt_in_time(values, t, ToneMapping(tau_cone=0.0, tau_rod=0.0)), values)
    assert np.array_equal(adapt_in_time(values[:4], t[:4], params), s[:4])  # causal: later frames change nothing
    assert np.all(adapt_in_time(np.full(5, 0.3), t[:5], params) == 0.3)  # a still scene holds still


def test_tonemap_is_monotone_srgb_8bit():
    ramp = np.linspace(0, 10, 50)[:, None] * np.ones(3)
    out = tonemap(ramp, 1.0, ToneMapping(operator="ward"))
    assert out.dtype == np.uint8 and np.all(np.diff(out[:, 0].astype(int)) >= 0) and out[-1, 0] == 255
    assert srgb_encode(np.array([0.0, 0.0031308, 1.0])).tolist() == pytest.approx([0.0, 0.04045, 1.0], abs=1e-5)
    with pytest.raises(LoomError):
        ToneMapping(display_max=0)


@pytest.mark.parametrize("operator", ["filmic", "exposure", "ward"])
def test_every_operator_is_monotone_and_bounded(operator):
    ramp = np.geomspace(1e-6, 1e4, 200)[:, None] * np.ones(3)
    out = display_linear(ramp, 0.05, ToneMapping(operator=operator))
    assert np.all(np.diff(out[:, 0]) >= 0) and out.min() >= 0 and out.max() == pytest.approx(1.0, abs=0.02)
    assert np.all(np.isfinite(display_linear(np.zeros((2, 3)), 0.0, ToneMapping(operator=operator))))


def test_exposure_operator_puts_the_adaptation_on_middle_grey_and_ev_doubles():
    la = 0.057  # a dim room's adaptation luminance (ROOM's): shown at middle grey, not at Ward's 1.7 %
    grey = np.full((1, 3), la)
    assert display_linear(grey, la, ToneMapping(operator="exposure"))[0, 0] == pytest.approx(KEY)
    one_up = display_linear(grey, la, ToneMapping(operator="exposure", exposure=1.0))[0, 0]
    assert one_up == pytest.approx(2 * KEY)
    ward = display_linear(grey, la, ToneMapping(operator="ward"))[0, 0]
    assert ward == pytest.approx(ward_scale(la) * la / 100.0) and ward < 0.03
    # Ward's operator takes EV too: a factor 2^EV on its scale
    assert display_linear(grey, la, ToneMapping(operator="ward", exposure=-2.0))[0, 0] == pytest.approx(ward / 4)


def test_filmic_curve_is_narkowicz_aces_fit_with_a_shoulder():
    x = np.array([0.0, KEY, 1.0, 100.0])
    expected = x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14)
    np.testing.assert_allclose(aces_filmic(x), np.minimum(expected, 1.0))
    grey = display_linear(np.full((1, 3), 2.0), 2.0, ToneMapping())[0, 0]
    assert grey == pytest.approx(aces_filmic(np.array([KEY]))[0])  # adaptation at the key, then the curve
    # highlights roll off: 8x the key is not clipped, unlike the linear exposure
    bright = np.full((1, 3), 8 * 2.0 / KEY * KEY)
    assert display_linear(bright, 2.0, ToneMapping())[0, 0] < 1.0
    assert display_linear(bright, 2.0, ToneMapping(operator="exposure"))[0, 0] == 1.0


def test_bad_operator_and_exposure_are_one_line_errors():
    with pytest.raises(LoomError, match="tonemap"):
        ToneMapping(operator="reinhard")
    with pytest.raises(LoomError, match="exposure"):
        ToneMapping(exposure=float("nan"))
