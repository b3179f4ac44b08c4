"""Contrast sensitivity: Daly's static CSF and the Kelly/Daly spatiovelocity CSF with smooth pursuit.

Sensitivity S is 1 / (threshold Michelson contrast) for a grating of radial frequency rho (cy/deg).
The AQM's CSF is S(rho, l, v) = S_Daly(rho, l) * V(rho, v_R):
  * S_Daly (Daly 1993) gives the shape and the adaptation-luminance dependence for still viewing;
  * V = min(1, S_KD(rho, v_R) / S_KD(rho, v_drift)) is the loss of sensitivity at retinal velocity v_R
    from Kelly's (1979) spatiovelocity surface as rescaled by Daly (1998). Still viewing is v_R = drift
    (0.15 deg/s, Daly 1998), where V = 1, so a still or perfectly tracked frame uses exactly Daly's CSF.
    Ratios above 1 (low frequencies at high v_R, where Kelly's stabilised-like drift curve falls below
    Daly's unstabilised one) are not taken: that gain is an artefact of comparing two fits [decision].
Per-pixel luminance and velocity are applied by filtering with a bank of CSFs at fixed levels and
interpolating the filtered images per pixel (HDR-VDP 1.x scheme, docs/08-aqm.md §2a-2b); see
:func:`space_variant_filter`.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import numpy.typing as npt

# --- Daly 1993, static CSF (docs/08-aqm.md §2a) ---------------------------------------------------
DALY_P = 250.0  # absolute peak scale
DALY_EPS = 0.9  # epsilon
DALY_OB = 0.78  # oblique effect
DALY_KE = 0.24  # eccentricity
# --- Kelly 1979 / Daly 1998 spatiovelocity CSF (docs/08-aqm.md §2b) ------------------------------
KD_C0, KD_C1, KD_C2 = 1.14, 0.67, 1.7
# --- Daly 1998 eye movements ---------------------------------------------------------------------
G_SP = 0.82  # smooth-pursuit gain
V_DRIFT = 0.15  # deg/s, drift: minimum eye (and retinal) velocity
V_MAX = 80.0  # deg/s, saccade limit of pursuit
# --- filter-bank levels for per-pixel interpolation ---------------------------------------------
LUMINANCE_LEVELS = 10.0 ** np.arange(-3, 5)  # cd/m^2, decades (HDR-VDP 1.x uses decades too)
VELOCITY_LEVELS = V_DRIFT * 2.0 ** np.arange(10)  # 0.15 ... 76.8 deg/s, octaves


def _daly_s1(rho, lum, i2):
    a_l = 0.801 * (1.0 + 0.7 / lum) ** -0.2
    b_l = 0.3 * (1.0 + 100.0 / lum) ** 0.15
    with np.errstate(divide="ignore"):
        size = ((3.23 * (rho**2 * i2) ** -0.3) ** 5 + 1.0) ** -0.2
    x = b_l * DALY_EPS * rho
    return size * a_l * DALY_EPS * rho * np.exp(-x) * np.sqrt(1.0 + 0.06 * np.exp(x))


def daly_csf(rho: npt.ArrayLike, lum: float, *, i2: float, distance_m: float, theta: npt.ArrayLike = 0.0,
             eccentricity: float = 0.0) -> np.ndarray:
    """Daly's (1993) static CSF S(rho, theta, l, i^2, d, e); rho in cy/deg, l in cd/m^2, i^2 in deg^2.

    S = P min[S1(rho / (r_a r_e r_theta)), S1(rho)]; S(0) = 0 (the DC is not a contrast).
    """
    rho = np.asarray(rho, dtype=np.float64)
    r_a = 0.856 * distance_m**0.14
    r_e = 1.0 / (1.0 + DALY_KE * eccentricity)
    r_theta = (1.0 - DALY_OB) / 2.0 * np.cos(4.0 * np.asarray(theta)) + (1.0 + DALY_OB) / 2.0
    with np.errstate(invalid="ignore", divide="ignore"):
        s = DALY_P * np.minimum(_daly_s1(rho / (r_a * r_e * r_theta), lum, i2), _daly_s1(rho, lum, i2))
    return np.where(rho > 0, np.nan_to_num(s), 0.0)


def kelly_daly_csf(rho: npt.ArrayLike, velocity: npt.ArrayLike) -> np.ndarray:
    """Kelly's (1979) spatiovelocity CSF with Daly's (1998) constants; rho cy/deg, velocity deg/s (>0)."""
    rho = np.asarray(rho, dtype=np.float64)
    cv = KD_C2 * np.asarray(velocity, dtype=np.float64)
    k = 6.1 + 7.3 * np.abs(np.log10(cv / 3.0)) ** 3
    rho_max = 45.9 / (cv + 2.0)
    return KD_C0 * k * cv * (2.0 * np.pi * KD_C1 * rho) ** 2 * np.exp(-4.0 * np.pi * KD_C1 * rho / rho_max)


def velocity_factor(rho: npt.ArrayLike, velocity: npt.ArrayLike) -> np.ndarray:
    """V(rho, v_R) = min(1, S_KD(rho, v_R) / S_KD(rho, drift)): loss of sensitivity with retinal velocity."""
    rho = np.maximum(np.asarray(rho, dtype=np.float64), 1e-6)  # the ratio has a finite limit at rho -> 0
    return np.minimum(1.0, kelly_daly_csf(rho, velocity) / kelly_daly_csf(rho, V_DRIFT))


def retinal_velocity(image_velocity: npt.ArrayLike, pursuit_gain: float = G_SP) -> np.ndarray:
    """Retinal speed v_R (deg/s) of image regions moving at ``image_velocity`` deg/s (Daly 1998).

    The eye pursues at v_E = min(g v_I + v_drift, v_max) and v_R = |v_I - v_E|, clamped to
    [v_drift, v_max]: gain 0 is an eye that does not follow the motion, 1 one that tracks it fully,
    0.82 Daly's average smooth pursuit. Inputs of shape (..., 2) are velocity vectors.
    """
    v = np.asarray(image_velocity, dtype=np.float64)
    if v.ndim == 3 and v.shape[-1] == 2:
        v = np.hypot(v[..., 0], v[..., 1])
    eye = np.minimum(pursuit_gain * v + V_DRIFT, V_MAX)
    return np.clip(np.abs(v - eye), V_DRIFT, V_MAX)


@lru_cache(maxsize=16)
def frequency_grid(shape: tuple[int, int], ppd: float) -> tuple[np.ndarray, np.ndarray]:
    """Radial frequency (cy/deg) and orientation (rad) of each rfft2 bin of an image of ``shape``."""
    fy = np.fft.fftfreq(shape[0])[:, None] * ppd
    fx = np.fft.rfftfreq(shape[1])[None, :] * ppd
    return np.hypot(fx, fy), np.arctan2(fy, fx)


@lru_cache(maxsize=16)
def luminance_bank(shape: tuple[int, int], ppd: float, i2: float, distance_m: float) -> np.ndarray:
    """Daly CSF transfer functions at LUMINANCE_LEVELS, shape (K, H, W//2 + 1)."""
    rho, theta = frequency_grid(shape, ppd)
    bank = np.stack([daly_csf(rho, lum, i2=i2, distance_m=distance_m, theta=theta) for lum in LUMINANCE_LEVELS])
    bank.setflags(write=False)
    return bank


@lru_cache(maxsize=16)
def velocity_bank(shape: tuple[int, int], ppd: float) -> np.ndarray:
    """Velocity factors V(rho, v_j) at VELOCITY_LEVELS, shape (K, H, W//2 + 1)."""
    rho, _ = frequency_grid(shape, ppd)
    bank = np.stack([velocity_factor(rho, v) for v in VELOCITY_LEVELS])
    bank.setflags(write=False)
    return bank


def luminance_coordinate(adaptation: np.ndarray) -> np.ndarray:
    """Fractional index into LUMINANCE_LEVELS of each pixel's adaptation luminance (log10 spacing).

    Rounded to 1e-6 so FFT round-off on a uniform field does not call in a neighbouring filter.
    """
    return np.round(np.clip(np.log10(adaptation) - np.log10(LUMINANCE_LEVELS[0]), 0.0, len(LUMINANCE_LEVELS) - 1.0), 6)


def velocity_coordinate(v_retinal: np.ndarray) -> np.ndarray:
    """Fractional index into VELOCITY_LEVELS of each pixel's retinal velocity (log2 spacing), rounded to 1e-6."""
    return np.round(np.clip(np.log2(v_retinal / V_DRIFT), 0.0, len(VELOCITY_LEVELS) - 1.0), 6)


def space_variant_filter(spectrum: np.ndarray, shape: tuple[int, int], bank: np.ndarray,
                         coord: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Filter with a per-pixel transfer function interpolated linearly between bank entries.

    ``coord`` holds each pixel's fractional index into ``bank``. Returns (spectrum, None) when every
    pixel sits on the same bank entry (the filter is then space-invariant and no FFT is needed), else
    (None, image): the sum over entries j of hat(coord - j) * irfft2(spectrum * bank[j]).
    """
    lo, hi = int(np.floor(coord.min())), int(np.ceil(coord.max()))
    if lo == hi:
        return spectrum * bank[lo], None
    out = np.zeros(shape)
    for j in range(lo, hi + 1):
        weight = np.maximum(0.0, 1.0 - np.abs(coord - j))
        if weight.any():
            out += weight * np.fft.irfft2(spectrum * bank[j], s=shape)
    return None, out
