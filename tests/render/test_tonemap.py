"""Tone mapping (Ward 1994) and temporal adaptation (Pattanaik et al. 2000): closed forms."""
from __future__ import annotations

import numpy as np
import pytest

from pipeline.errors import LoomError
from pipeline.tonemap import (ToneMapping, log_average, smooth_adaptation, srgb_encode, tonemap,
                              ward_scale)


def test_ward_scale_closed_form():
    assert ward_scale(50.0, 100.0) == pytest.approx(1.0)  # adapted to half the display's white
    la = 0.3
    assert ward_scale(la) == pytest.approx(((1.219 + 50 ** 0.4) / (1.219 + la ** 0.4)) ** 2.5)
    assert ward_scale(0.01) > ward_scale(1.0) > ward_scale(100.0)  # dimmer worlds are scaled up


def test_log_average_is_geometric_mean_and_survives_zeros():
    assert log_average(np.array([1.0, 100.0]) - 1e-4) == pytest.approx(10.0)
    assert np.isfinite(log_average(np.zeros(5))) and log_average(np.zeros(0)) > 0


def test_smoothing_follows_a_step_exponentially_in_log_space():
    t = np.arange(6) / 30.0
    values = np.array([1.0, 1.0, 100.0, 100.0, 100.0, 100.0])
    s = smooth_adaptation(values, t, tau=0.1)
    a = 1 - np.exp(-(1 / 30) / 0.1)
    assert s[1] == pytest.approx(1.0) and np.log10(s[2]) == pytest.approx(2 * a)
    assert np.all(np.diff(s[1:]) > 0) and s[-1] < 100.0  # no jump, approaches the new level
    np.testing.assert_allclose(smooth_adaptation(values, t, tau=0.0), values)  # tau 0: no smoothing


def test_tonemap_is_monotone_srgb_8bit():
    ramp = np.linspace(0, 10, 50)[:, None] * np.ones(3)
    out = tonemap(ramp, 1.0)
    assert out.dtype == np.uint8 and np.all(np.diff(out[:, 0].astype(int)) >= 0) and out[-1, 0] == 255
    assert srgb_encode(np.array([0.0, 0.0031308, 1.0])).tolist() == pytest.approx([0.0, 0.04045, 1.0], abs=1e-5)
    with pytest.raises(LoomError):
        ToneMapping(display_max=0)
