"""Test data for the AQM tests: gratings, textures, Monte Carlo-like noise, threshold search."""
from __future__ import annotations

import numpy as np

from pipeline.aqm import ViewingConditions, aqm_luminance

SIZE = 256
GRATING_PPD = 64.0  # 256 px span 4 degrees; 0.5..16 cpd are 2..64 whole cycles (periodic, no leakage)


def grating(freq_cpd: float, ppd: float = GRATING_PPD, size: int = SIZE) -> np.ndarray:
    """Vertical-bar cosine grating (unit amplitude) with a whole number of cycles across the image."""
    cycles = freq_cpd / ppd * size
    assert cycles == round(cycles), "grating must be periodic in the image"
    return np.broadcast_to(np.cos(2 * np.pi * cycles * np.arange(size) / size), (size, size))


def threshold_contrast(freq_cpd: float, background: float, viewing: ViewingConditions, steps: int = 18,
                       **kwargs) -> float:
    """Michelson contrast at which the AQM's peak detection probability crosses 0.75 (bisection in log c).

    The peak is taken over the central half of the field: at the image borders the grating meets its
    mirror image (metric.PAD_FRACTION), a different stimulus from the full-field grating of the CSF.
    """
    pattern = grating(freq_cpd, viewing.ppd)
    size = pattern.shape[0]
    field = np.full((size, size), background)
    lo, hi = -4.0, 0.0
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        result = aqm_luminance(field, background * (1 + 10**mid * pattern), viewing=viewing, **kwargs)
        centre = result.map[size // 4: -size // 4, size // 4: -size // 4]
        lo, hi = (lo, mid) if centre.max() > 0.75 else (mid, hi)
    return 10**hi


def smooth_noise(rng: np.random.Generator, sigma_px: float, size: int = SIZE) -> np.ndarray:
    """Gaussian-filtered white noise with unit standard deviation (a random texture)."""
    spectrum = np.fft.rfft2(rng.standard_normal((size, size)))
    fy = np.fft.fftfreq(size)[:, None]
    fx = np.fft.rfftfreq(size)[None, :]
    field = np.fft.irfft2(spectrum * np.exp(-2 * np.pi**2 * sigma_px**2 * (fx**2 + fy**2)), s=(size, size))
    return field / field.std()


def monte_carlo(image: np.ndarray, samples: int, seed: int) -> np.ndarray:
    """``image`` estimated with ``samples`` exponential samples per pixel: unbiased, variance ~ 1/samples."""
    rng = np.random.default_rng(seed)
    return image * rng.gamma(samples, 1.0 / samples, size=image.shape[:2])[..., None]
