"""Psychometric function and probability summation over channels (Daly 1993, docs/08-aqm.md §5).

P_c = 1 - exp(-|dC_c / Te_c|^beta), beta = 3.5 (Daly's patent, HDR-VDP 1.x default), for each of the 31
cortex channels c (Te_c: the masking elevation of c's radial band); over the channels
P = 1 - prod_c (1 - P_c) = 1 - exp(-sum_c |dC_c / Te_c|^beta).

Threshold: a pixel shows a visible difference when P > 0.75. That is the 1 JND level of the paper's
d_AQM ("differences over one unit JND", §5.2.3): 0.75 is the classic 2AFC/75 % detection criterion
and the figure Myszkowski's AQM reports ("P(>0.75)"); it is crossed at |dC/Te| = (ln 4)^(1/beta) = 1.10,
i.e. about one CSF threshold.
"""
from __future__ import annotations

import numpy as np

BETA = 3.5  # Daly 1993 psychometric slope
P_THRESHOLD = 0.75  # 1 JND, see module docstring


def detection_probability(delta: np.ndarray, elevation: np.ndarray, beta: float = BETA,
                          band: np.ndarray | None = None) -> np.ndarray:
    """Per-pixel P from channel differences ``delta`` (channels, H, W) and elevations ``elevation``.

    ``elevation`` has one map per channel, or one per radial band with ``band`` giving each channel's band.
    """
    summed = np.zeros(delta.shape[1:])
    for c in range(delta.shape[0]):
        x = np.abs(delta[c]) / elevation[c if band is None else band[c]]
        if beta == 3.5:  # Daly's beta: x^3 sqrt(x), a third of the time of a power
            summed += x * x * x * np.sqrt(x)
        else:
            summed += x**beta
    return -np.expm1(-summed)


def d_aqm(probability: np.ndarray, threshold: float = P_THRESHOLD) -> float:
    """d_AQM: percentage of pixels whose detection probability exceeds ``threshold`` (§5.2.3)."""
    return float(100.0 * np.count_nonzero(probability > threshold) / probability.size)
