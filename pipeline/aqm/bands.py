"""Daly's (1993) cortex transform (Watson 1987): radial bands, and radial x orientation channels.

Radial frequency bands, in cycles per pixel: band k (k = 1..5) lies between mesa(rho; 2^-k) and
mesa(rho; 2^-(k-1)) (Daly's "dom" filters d_k), the base band below 1/32 cy/px (docs/08-aqm.md §3). Each dom
band is split into six orientations by Daly's fan filters fan_l(theta), raised cosines 30 deg wide about
theta_l = -90 + 30 l deg: 5 x 6 + 1 = 31 channels, as in Daly's VDP. §6 of the paper drops orientation
"in the visual masking" only, so detection uses the 31 channels and masking the six radial bands
(masking.py).

The transfer functions are Daly's own, d_k fan_l (and the base band), which sum to 1. A grating between
two channel centres then needs more contrast than one at a centre (probability summation of exponent
beta over channels, psychometric.py; at most 2^(1 - 1/beta) = 1.64x, 0.21 log units, for a pure grating
halfway between two orientations). Raising the filters to the power 1/beta would remove that ripple; on
ModelFest it fits worse (RMS 0.377 against 0.230 log10 units; 0.199 against 0.166 with a free gain,
docs/08-aqm.md §8), so the AQM keeps Daly's filters.

The band and channel images are inverse transforms in single precision (the spectra and filters
cast to float32): the 31 channels' inverse FFTs are most of the metric's time and take a third as
long, and the detection probabilities move by under 1e-6 (tests/aqm/test_stages.py).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

N_BANDS = 6  # 5 dom bands + base (Daly 1993)
N_ORIENTATIONS = 6  # Daly's (1993) fan filters, 30 degrees apart


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
def band_filters(shape: tuple[int, int]) -> np.ndarray:
    """Daly's radial band filters d_k (and the base band) for rfft2 spectra, shape (6, H, W//2 + 1)."""
    h = dom_filters(radial_frequency(shape))
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


def fan_filters(theta: np.ndarray) -> np.ndarray:
    """Daly's (1993) fan filters at orientations ``theta`` (rad), shape (6, ...); they sum to 1.

    fan_l = 0.5 [1 + cos(pi |theta - theta_l| / theta_tw)] for |theta - theta_l| <= theta_tw, else 0, with
    theta_tw = 30 deg and theta_l = -90 + 30 l deg; orientation differences are taken modulo 180 deg.
    """
    tw = np.pi / N_ORIENTATIONS
    centres = -np.pi / 2 + tw * np.arange(N_ORIENTATIONS)
    delta = np.abs((theta[None] - centres.reshape((-1,) + (1,) * theta.ndim) + np.pi / 2) % np.pi - np.pi / 2)
    return np.where(delta <= tw, 0.5 * (1.0 + np.cos(np.pi * np.minimum(delta / tw, 1.0))), 0.0)


@lru_cache(maxsize=16)
def channel_filters(shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Daly's transfer functions d_k fan_l of the 31 detection channels, and each one's radial band.

    Returns (filters (31, H, W//2 + 1), band index (31,)): 5 dom bands x 6 orientations, then the base.
    """
    fy = np.fft.fftfreq(shape[0])[:, None]
    fx = np.fft.rfftfreq(shape[1])[None, :]
    theta = np.arctan2(fy, fx) * np.ones_like(fx)
    dom = dom_filters(np.hypot(fx, fy))
    fans = fan_filters(theta)
    h = np.concatenate([(dom[:N_BANDS - 1, None] * fans[None]).reshape(-1, *theta.shape), dom[-1:]])
    band = np.append(np.repeat(np.arange(N_BANDS - 1), N_ORIENTATIONS), N_BANDS - 1)
    h.setflags(write=False)
    band.setflags(write=False)
    return h, band


@lru_cache(maxsize=16)
def _single(shape: tuple[int, int], channels: bool) -> np.ndarray:
    """The channel (or band) filters in float32, for the single-precision inverse transforms."""
    h = channel_filters(shape)[0] if channels else band_filters(shape)
    h = h.astype(np.float32)
    h.setflags(write=False)
    return h


def decompose(spectrum: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Band images (6, H, W) float32 of an rfft2 ``spectrum``, highest frequency first."""
    return np.fft.irfft2(spectrum.astype(np.complex64)[None] * _single(shape, False), s=shape)


def decompose_channels(spectrum: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Channel images (31, H, W) float32 of an rfft2 ``spectrum`` and each channel's radial band (channel_filters)."""
    return (np.fft.irfft2(spectrum.astype(np.complex64)[None] * _single(shape, True), s=shape),
            channel_filters(shape)[1])
