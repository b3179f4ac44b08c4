"""Tone mapping with eye adaptation: linear frames to 8-bit sRGB (dept.md §2).

Operator: Ward's contrast-based scale factor (G. Ward, "A contrast-based scalefactor for
luminance display", Graphics Gems IV, 1994). From Blackwell's threshold-versus-intensity curve
dL(La) = 0.0594 (1.219 + La^0.4)^2.5, matching a just-noticeable difference in the world to one
on the display gives one global scale  L_d = m L_w,  m = [(1.219 + (Ld_max/2)^0.4) /
(1.219 + L_wa^0.4)]^2.5, and the display value is clamp(L_d / Ld_max, 0, 1) encoded with the sRGB
transfer function. Why Ward: one monotone scalar, no iteration, easy to smooth over time, and it
maps visibility thresholds to visibility thresholds, the invariant behind "noise below what a
viewer sees" (§5); histogram methods are image-dependent and flicker.

Adaptation: L_wa is the log-average luminance of the frame's mesh-based lighting (direct estimate
plus indirect map, §4) over the vertices the camera sees, computed per frame before compositing.
Smoothing: a per-frame adaptation flickers (dept.md §4.6), so the adaptation level follows an
exponential filter in time, L_a(t) = L_a(t-1) + (L_wa(t) - L_a(t-1)) (1 - exp(-dt / tau))
(Pattanaik et al., SIGGRAPH 2000), run in log luminance (perceived brightness is roughly
logarithmic, so a step up and a step down adapt alike) over the frames of one render.
Units: one radiometric radiance unit is ``nits_per_unit`` cd/m^2 (1 by default, DESIGN.md units).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .errors import ConfigError

REC709_Y = np.array([0.2126, 0.7152, 0.0722])  # luminance of linear Rec.709 RGB (ITU-R BT.709)
DELTA = 1e-4  # cd/m^2 floor inside the log-average (Ward 1994; avoids log 0)


@dataclass(frozen=True, kw_only=True)
class ToneMapping:
    display_max: float = 100.0  # Ld_max, display white in cd/m^2 (Ward 1994)
    nits_per_unit: float = 1.0  # cd/m^2 per radiometric radiance unit
    tau: float = 0.4  # adaptation time constant in seconds (Pattanaik et al. 2000: 0.1-0.5 s)

    def __post_init__(self) -> None:
        for name in ("display_max", "nits_per_unit"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"invalid value {getattr(self, name)!r}: must be > 0", field=name)
        if not self.tau >= 0:
            raise ConfigError(f"invalid value {self.tau!r}: must be >= 0", field="tau")

    def to_dict(self) -> dict:
        return asdict(self)


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec.709 luminance of linear RGB (..., 3)."""
    return np.asarray(rgb, dtype=np.float64) @ REC709_Y


def log_average(lum: np.ndarray, weights: np.ndarray | None = None) -> float:
    """exp(weighted mean of log(DELTA + L)): the adaptation luminance of a set of samples."""
    lum = np.asarray(lum, dtype=np.float64)
    w = np.ones_like(lum) if weights is None else np.asarray(weights, dtype=np.float64)
    if lum.size == 0 or not w.sum() > 0:
        return DELTA
    return float(np.exp(np.sum(w * np.log(DELTA + np.maximum(lum, 0.0))) / w.sum()))


def ward_scale(adaptation: float, display_max: float = 100.0) -> float:
    """Ward's (1994) contrast-based scale factor m for world adaptation luminance L_wa (cd/m^2)."""
    num = 1.219 + (display_max / 2.0) ** 0.4
    den = 1.219 + max(float(adaptation), 0.0) ** 0.4
    return (num / den) ** 2.5


def smooth_adaptation(values, times, tau: float) -> np.ndarray:
    """Exponential temporal filter of adaptation luminances in log space (module docstring).

    ``values`` per frame in render order, ``times`` in seconds; the first frame starts adapted.
    """
    v = np.log(np.asarray(values, dtype=np.float64))
    t = np.asarray(times, dtype=np.float64)
    out = np.empty_like(v)
    for i in range(len(v)):
        if i == 0:
            out[i] = v[i]
            continue
        dt = abs(t[i] - t[i - 1])
        alpha = 1.0 if tau == 0 else 1.0 - np.exp(-dt / tau)
        out[i] = out[i - 1] + (v[i] - out[i - 1]) * alpha
    return np.exp(out)


def srgb_encode(x: np.ndarray) -> np.ndarray:
    """The sRGB transfer function (IEC 61966-2-1) of linear values in [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def tonemap(rgb: np.ndarray, adaptation: float, params: ToneMapping = ToneMapping()) -> np.ndarray:
    """uint8 sRGB image (..., 3) from linear radiance ``rgb`` at adaptation luminance ``adaptation``
    (radiance units, like ``rgb``; both are scaled by ``nits_per_unit`` to cd/m^2)."""
    m = ward_scale(adaptation * params.nits_per_unit, params.display_max)
    display = np.asarray(rgb, dtype=np.float64) * (params.nits_per_unit * m / params.display_max)
    return np.round(srgb_encode(display) * 255.0).astype(np.uint8)
