"""Visual masking with mutual masking (Daly 1993; constants as in HDR-VDP 1.x, docs/aqm.md §4).

A band signal m (in threshold units: 1 = just detectable) raises the detection threshold of a
difference in the same band by
    Te(m) = [1 + (k1 (k2 |m|)^s)^b]^(1/b),   k1 = W^(1 - 1/(1-Q)),  k2 = W^(1/(1-Q)),  W = 6, b = 4.
Daly gives Q = 0.7; the knee (where masking begins) is then at |m| = k1^(-1/s) / k2, which is one
threshold only when s = Q. We set Q = s for each band so every band starts masking at one JND of
the masker (W then cancels: Te = [1 + |m|^(s b)]^(1/b)) [decision]. Mutual masking takes the smaller
elevation of the two images so an error does not mask itself: Te = max(1, min(Te_a, Te_b)).
"""
from __future__ import annotations

import numpy as np

from .bands import MASKING_SLOPE, phase_uncertainty_filters

MASKING_B = 4.0  # Daly 1993


def threshold_elevation(m: np.ndarray, slope: float, b: float = MASKING_B) -> np.ndarray:
    """Daly's threshold elevation for band signal ``m`` (threshold units) and masking slope ``slope``.

    With Q = s, k1 (k2 |m|)^s = |m|^s for any W, so Te = [1 + |m|^(s b)]^(1/b) (module docstring).
    """
    base = 1.0 + np.abs(m) ** (slope * b)
    if b == 4.0:  # Daly's b: two square roots, 2 ms of a power's 5 on an AQM band, to the last bit or two
        return np.sqrt(np.sqrt(base, out=base), out=base)
    return base ** (1.0 / b)


def mutual_masking(bands_a: np.ndarray, bands_b: np.ndarray) -> np.ndarray:
    """Per-band threshold elevation (6, H, W) from both images' band signals, with phase uncertainty.

    Te_k = max(1, LP_k[min(Te(m_a,k), Te(m_b,k))]) with LP_k the band's phase-uncertainty low-pass.
    """
    shape = bands_a.shape[1:]
    lp = phase_uncertainty_filters(shape)
    out = np.empty_like(bands_a)
    for k, slope in enumerate(MASKING_SLOPE):
        te = np.minimum(threshold_elevation(bands_a[k], slope), threshold_elevation(bands_b[k], slope))
        out[k] = np.fft.irfft2(np.fft.rfft2(te) * lp[k], s=shape)
    return np.maximum(out, 1.0)
