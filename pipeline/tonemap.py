"""Tone mapping with eye adaptation: linear frames to 8-bit sRGB (docs/estimators.md §2).

Three operators (``ToneMapping.operator``, ``loom render --tonemap``), all driven by the same
smoothed adaptation luminance L_a and shifted by ``exposure`` EV (a factor 2^EV):

* ``filmic`` (default): the frame exposed so that L_a lands on middle grey 0.18 (the "key" of
  Reinhard et al., SIGGRAPH 2002), then Narkowicz's fit of the ACES filmic curve
  (K. Narkowicz, "ACES Filmic Tone Mapping Curve", 2016) per channel: a toe, a long shoulder
  that rolls highlights off instead of clipping them. Chosen as the default because it shows a
  dim scene such as ROOM as a photographer would expose it (lit walls, colour bleeding, the
  highlight) where Ward's operator shows it as dim as it is.
* ``exposure``: the same key exposure, linear, clipped at white: what a camera's meter gives.
* ``ward``: Ward's visibility-matching scale factor, below: the display shows what a viewer
  adapted to the real scene would see, so a dim room stays dim.

The AQM (pipeline/perceived.py) always judges with Ward's operator whatever the look chosen:
visibility predictions need the scene's absolute luminances, and a change of look then neither
re-decides segments nor traces photons again (pipeline/render.py keeps the look out of the
decision hash).

Ward's operator: Ward's contrast-based scale factor (G. Ward, "A contrast-based scalefactor for
luminance display", Graphics Gems IV, 1994). From Blackwell's threshold-versus-intensity curve
dL(La) = 0.0594 (1.219 + La^0.4)^2.5, matching a just-noticeable difference in the world to one
on the display gives one global scale  L_d = m L_w,  m = [(1.219 + (Ld_max/2)^0.4) /
(1.219 + L_wa^0.4)]^2.5, and the display value is clamp(L_d / Ld_max, 0, 1) encoded with the sRGB
transfer function. Why Ward: one monotone scalar, no iteration, easy to smooth over time, and it
maps visibility thresholds to visibility thresholds, the invariant behind "noise below what a
viewer sees" (§5); histogram methods are image-dependent and flicker.

Adaptation: L_wa is the log-average luminance of the frame's mesh-based lighting (direct estimate
plus indirect map, §4) over the vertices the camera sees, computed per frame before compositing.
Smoothing: a per-frame adaptation flickers (docs/estimators.md §2.2), so the adaptation level follows an
exponential filter in time, L_a(t) = L_a(t-1) + (L_wa(t) - L_a(t-1)) (1 - exp(-dt / tau))
(Pattanaik et al., SIGGRAPH 2000), run in log luminance (perceived brightness is roughly
logarithmic, so a step up and a step down adapt alike) over the frames of one render.
Units: one radiometric radiance unit is ``nits_per_unit`` cd/m^2 (1 by default, docs/conventions.md §1).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import numpy.typing as npt

from kernels.colour import LUMA

from .aqm.display import DISPLAYS, FILLS
from .errors import ConfigError

DELTA = 1e-4  # cd/m^2 floor inside the log-average (Ward 1994; avoids log 0)
OPERATORS = ("filmic", "exposure", "ward")
KEY = 0.18  # middle grey the adaptation luminance is exposed to (Reinhard et al. 2002)
LOOK_FIELDS = ("operator", "exposure")  # what only the displayed look reads, never the AQM


@dataclass(frozen=True, kw_only=True)
class ToneMapping:
    display_max: float = 100.0  # Ld_max, display white in cd/m^2 (Ward 1994)
    nits_per_unit: float = 1.0  # cd/m^2 per radiometric radiance unit
    tau: float = 0.4  # adaptation time constant in seconds (Pattanaik et al. 2000: 0.1-0.5 s)
    operator: str = "filmic"  # filmic | exposure | ward (module docstring)
    exposure: float = 0.0  # EV added to the operator's own exposure (a factor 2^EV)
    # Where the frames are watched, for the AQM (§6, pipeline/perceived.py viewing_for): a display
    # of ColorVideoVDP's (its size, resolution and distance) and how a frame fills it
    display: str = "standard_fhd"
    fill: str = "full_screen"

    def __post_init__(self) -> None:
        if self.operator not in OPERATORS:
            raise ConfigError(f"invalid value {self.operator!r}: must be one of {', '.join(OPERATORS)}",
                              field="tonemap")
        for name, known in (("display", DISPLAYS), ("fill", FILLS)):
            if getattr(self, name) not in known:
                raise ConfigError(f"invalid value {getattr(self, name)!r}: must be one of {', '.join(known)}",
                                  field=f"--{name}")
        if isinstance(self.exposure, bool) or not isinstance(self.exposure, (int, float)) \
                or not -30.0 <= self.exposure <= 30.0:
            raise ConfigError(f"invalid value {self.exposure!r}: must be a number of EV in [-30, 30]",
                              field="exposure")
        for name in ("display_max", "nits_per_unit"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"invalid value {getattr(self, name)!r}: must be > 0", field=name)
        if not self.tau >= 0:
            raise ConfigError(f"invalid value {self.tau!r}: must be >= 0", field="tau")

    def to_dict(self) -> dict[str, float | str]:
        return asdict(self)


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec.709 luminance of linear RGB (..., 3)."""
    return np.asarray(rgb, dtype=np.float64) @ np.asarray(LUMA)


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


def smooth_adaptation(values: npt.ArrayLike, times: npt.ArrayLike, tau: float) -> np.ndarray:
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


def aces_filmic(x: np.ndarray) -> np.ndarray:
    """Narkowicz's (2016) rational fit of the ACES filmic curve, clipped to [0, 1]."""
    x = np.maximum(np.asarray(x, np.float64), 0.0)
    return np.clip(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0)


def display_linear(rgb: np.ndarray, adaptation: float, params: ToneMapping = ToneMapping()) -> np.ndarray:
    """Linear display values in [0, 1] (1 = the display's white) of linear radiance ``rgb`` at
    adaptation luminance ``adaptation`` (radiance units, like ``rgb``) under ``params.operator``."""
    rgb = np.asarray(rgb, dtype=np.float64)
    gain = 2.0 ** float(params.exposure)
    if params.operator == "ward":
        m = ward_scale(adaptation * params.nits_per_unit, params.display_max)
        return np.clip(rgb * (gain * params.nits_per_unit * m / params.display_max), 0.0, 1.0)
    exposed = rgb * (gain * KEY / max(float(adaptation), DELTA / params.nits_per_unit))
    return aces_filmic(exposed) if params.operator == "filmic" else np.clip(exposed, 0.0, 1.0)


def tonemap(rgb: np.ndarray, adaptation: float, params: ToneMapping = ToneMapping()) -> np.ndarray:
    """uint8 sRGB image (..., 3) from linear radiance ``rgb`` at adaptation luminance ``adaptation``
    (radiance units, like ``rgb``; Ward's operator scales both by ``nits_per_unit`` to cd/m^2)."""
    return np.round(srgb_encode(display_linear(rgb, adaptation, params)) * 255.0).astype(np.uint8)
