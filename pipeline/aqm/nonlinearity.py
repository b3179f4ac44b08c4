"""Amplitude nonlinearity with local adaptation (Daly 1993), expressed as contrast.

Daly's cone-like compression of luminance L at adaptation luminance L_a is
    R(L) = L / (L + c1 * L_a**b),   c1 = 12.6, b = 0.63     (Daly 1993, VDP "amplitude nonlinearity").
We divide the deviation from the adapted response by the small-signal gain at L_a,
    E = (R(L) - R(L_a)) / (L_a * dR/dL(L_a)) = (L - L_a)/L_a * (L_a + k)/(L + k),   k = c1 * L_a**b,
so E equals Weber contrast for small deviations (the CSF of csf.py, measured in luminance contrast,
then gives thresholds directly) and is compressed for large ones, as Daly's R is [decision, notes §1/§4].
L_a is the local adaptation: a Gaussian low-pass (sigma = 1 degree) of the mean luminance of both
images, so both are judged at the same adaptation and the metric stays symmetric [decision].
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

DALY_C1 = 12.6  # Daly 1993, amplitude nonlinearity
DALY_B = 0.63  # Daly 1993, amplitude nonlinearity
ADAPTATION_SIGMA_DEG = 1.0  # spatial extent of local adaptation, degrees [decision: ~foveal size]
MIN_ADAPTATION = 1e-3  # cd/m^2; keeps a black (0 cd/m^2) display region finite


def daly_response(lum: np.ndarray, adaptation: np.ndarray) -> np.ndarray:
    """Daly's (1993) nonlinearity R = L / (L + c1 L_a^b), in [0, 1)."""
    return lum / (lum + DALY_C1 * adaptation**DALY_B)


@lru_cache(maxsize=16)
def _gaussian_transfer(shape: tuple[int, int], sigma_px: float) -> np.ndarray:
    fy = np.fft.fftfreq(shape[0])[:, None]
    fx = np.fft.rfftfreq(shape[1])[None, :]
    return np.exp(-2.0 * np.pi**2 * sigma_px**2 * (fx**2 + fy**2))


def local_adaptation(lum_a: np.ndarray, lum_b: np.ndarray, ppd: float,
                     sigma_deg: float = ADAPTATION_SIGMA_DEG) -> np.ndarray:
    """Adaptation luminance L_a(x): Gaussian low-pass (sigma in degrees) of the two images' mean.

    Filtering is done with the FFT (periodic borders, like every other filter of the AQM).
    """
    mean = 0.5 * (lum_a + lum_b)
    blurred = np.fft.irfft2(np.fft.rfft2(mean) * _gaussian_transfer(mean.shape, sigma_deg * ppd), s=mean.shape)
    return np.maximum(blurred, MIN_ADAPTATION)


def nonlinear_contrast(lum: np.ndarray, adaptation: np.ndarray) -> np.ndarray:
    """Daly's response as luminance-equivalent contrast E = (L - L_a)/L_a * (L_a + k)/(L + k).

    Equal to (R(L) - R(L_a)) / (L_a R'(L_a)) with R of :func:`daly_response` (derivation in the module
    docstring); E -> Weber contrast as L -> L_a, E <= 1 + c1 L_a^(b-1) as L -> infinity.
    """
    k = DALY_C1 * adaptation**DALY_B
    return (lum - adaptation) / adaptation * (adaptation + k) / (lum + k)
