"""Radial band decomposition without orientation channels (cortex transform, Watson 1987; Daly 1993).

§6 of the paper drops the orientation channels of Daly's 31-channel cortex transform; what is left is
five radial "dom" bands and a base band (docs/aqm.md §3), in cycles per pixel: band k (k = 1..5) lies
between mesa(rho; 2^-k) and mesa(rho; 2^-(k-1)), the base band below 1/32 cy/px.

Daly's dom filters d_k sum to 1. With probability summation of exponent beta over bands (psychometric.py)
a grating falling between two bands would then need up to 0.2 log units more contrast than one at a
band centre, which contradicts the CSF the model is built on. We therefore use h_k = d_k^(1/beta):
sum_k h_k(rho)^beta = 1 for every rho, so a grating of any frequency reaches the same summed response
and its threshold is exactly 1/CSF [decision].
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

N_BANDS = 6  # 5 dom bands + base (Daly 1993 without orientation, §6 of the paper)
# Masking slope per band, highest frequency first: 1.0 for the high bands, 0.8 for the two lowest dom
# bands, 0.7 for the base (Daly's patent as quoted in HDR-VDP 1.x, docs/aqm.md §4).
MASKING_SLOPE = (1.0, 1.0, 1.0, 0.8, 0.8, 0.7)


def mesa(rho: np.ndarray, rho_h: float) -> np.ndarray:
    """Watson's (1987) mesa low-pass: 1 below rho_h - tw/2, raised-cosine to 0 at rho_h + tw/2, tw = 2/3 rho_h."""
    tw = 2.0 / 3.0 * rho_h
    t = np.clip((rho - rho_h + tw / 2.0) / tw, 0.0, 1.0)
    return 0.5 * (1.0 + np.cos(np.pi * t))


def base_band(rho: np.ndarray) -> np.ndarray:
    """Daly's (1993) Gaussian base band below rho_h,5 + tw_5 / 2 (rho_h,5 = 1/32 cy/px)."""
    edge = 2.0**-5 * (1.0 + 1.0 / 3.0)
    sigma = edge / 3.0
    return np.where(rho < edge, np.exp(-(rho**2) / (2.0 * sigma**2)), 0.0)


def dom_filters(rho: np.ndarray) -> np.ndarray:
    """Daly's dom filters d_1..d_5 and the base band at radial frequencies ``rho`` (cy/px); they sum to ~1."""
    lows = [mesa(rho, 2.0**-k) for k in range(N_BANDS - 1)]
    base = base_band(rho)
    bands = [lows[k - 1] - lows[k] for k in range(1, N_BANDS - 1)] + [lows[-1] - base, base]
    return np.clip(np.stack(bands), 0.0, None)


def radial_frequency(shape: tuple[int, int]) -> np.ndarray:
    """Radial frequency in cycles per pixel of each rfft2 bin."""
    fy = np.fft.fftfreq(shape[0])[:, None]
    fx = np.fft.rfftfreq(shape[1])[None, :]
    return np.hypot(fx, fy)


@lru_cache(maxsize=16)
def band_filters(shape: tuple[int, int], beta: float) -> np.ndarray:
    """Transfer functions h_k = d_k^(1/beta) of the bands for rfft2 spectra, shape (6, H, W//2 + 1)."""
    h = dom_filters(radial_frequency(shape)) ** (1.0 / beta)
    h.setflags(write=False)
    return h


@lru_cache(maxsize=16)
def phase_uncertainty_filters(shape: tuple[int, int]) -> np.ndarray:
    """Low-pass per band for the threshold-elevation maps, Daly's (1993) "phase uncertainty".

    Band k's mesa low-pass at its lower edge rho_h,k removes the 2x-frequency ripple of |band signal|,
    so a sinusoidal masker masks at its zero crossings too. Shape (6, H, W//2 + 1).
    """
    rho = radial_frequency(shape)
    f = np.stack([mesa(rho, 2.0 ** -(k + 1)) for k in range(N_BANDS)])
    f.setflags(write=False)
    return f


def decompose(spectrum: np.ndarray, shape: tuple[int, int], beta: float) -> np.ndarray:
    """Band images (6, H, W) of an rfft2 ``spectrum``, highest frequency first."""
    return np.fft.irfft2(spectrum[None] * band_filters(shape, beta), s=shape)
