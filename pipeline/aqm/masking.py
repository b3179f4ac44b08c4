"""Visual masking with mutual masking (Daly 1993, docs/08-aqm.md §4), computed on the radial bands (§6).

A band signal m (in threshold units: 1 = just detectable) raises the detection threshold of a
difference in the same band by Daly's (1993) threshold elevation
    Te(m) = [1 + (k1 (k2 |m|)^s)^b]^(1/b),   k1 = W^(1 - 1/(1-Q)),  k2 = W^(1/(1-Q)),
with Daly's W = 6, Q = 0.7, b = 4. Daly's learning slope s ranges from 0.65 to 1; s = 0.65 is the value
that reproduces the threshold-versus-masker-contrast curve of a grating masker (Legge & Foley, JOSA 70(12),
1980: no elevation by a masker near threshold, then a power law of exponent near 0.6). Through the whole
AQM it gives elevations 1.04, 1.36, 2.6 and 5.1 at maskers of 1, 3, 10 and 30 thresholds, slope 0.62
(docs/08-aqm.md §9); the knee of Te is then at |m| = (k1 k2^s)^(-1/s) = 1.58 thresholds.
Mutual masking takes the smaller elevation of the two images so an error does not mask itself:
Te = max(1, min(Te_a, Te_b)), after Daly's phase-uncertainty low-pass.
"""
from __future__ import annotations

import numpy as np

from .bands import N_BANDS, phase_uncertainty_filters

MASKING_W = 6.0  # Daly 1993, W
MASKING_Q = 0.7  # Daly 1993, Q
MASKING_B = 4.0  # Daly 1993, b
MASKING_S = 0.65  # Daly's learning slope s, the end of his 0.65..1 range that fits Legge & Foley (1980)


def threshold_elevation(m: np.ndarray, s: float = MASKING_S, w: float = MASKING_W, q: float = MASKING_Q,
                        b: float = MASKING_B) -> np.ndarray:
    """Daly's (1993) threshold elevation Te(m) = [1 + (k1 (k2 |m|)^s)^b]^(1/b) for band signal ``m``."""
    k1 = w ** (1.0 - 1.0 / (1.0 - q))
    k2 = w ** (1.0 / (1.0 - q))
    base = 1.0 + (k1 * (k2 * np.abs(m)) ** s) ** b
    if b == 4.0 and base.ndim:  # Daly's b: two square roots, faster than a power, to the last bit or two
        return np.sqrt(np.sqrt(base, out=base), out=base)
    return base ** (1.0 / b)


def mutual_masking(bands_a: np.ndarray, bands_b: np.ndarray) -> np.ndarray:
    """Per-band threshold elevation (6, H, W) from both images' band signals, with phase uncertainty.

    Te_k = max(1, LP_k[min(Te(m_a,k), Te(m_b,k))]) with LP_k the band's phase-uncertainty low-pass.
    """
    shape = bands_a.shape[1:]
    lp = phase_uncertainty_filters(shape)
    out = np.empty_like(bands_a)
    for k in range(N_BANDS):
        te = np.minimum(threshold_elevation(bands_a[k]), threshold_elevation(bands_b[k]))
        out[k] = np.fft.irfft2(np.fft.rfft2(te) * lp[k], s=shape)
    return np.maximum(out, 1.0)
