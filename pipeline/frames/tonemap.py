"""Tone mapping with eye adaptation: linear frames to 8-bit sRGB (docs/05-estimators.md §2).

Three operators (``ToneMapping.operator``, ``loom render --tonemap``), all driven by the same
time-adapted luminance L_a and shifted by ``exposure`` EV (a factor 2^EV):

* ``filmic`` (default): the frame exposed so that L_a lands on middle grey 0.18 (the "key" of
  Reinhard et al., SIGGRAPH 2002), then Narkowicz's fit of the ACES filmic curve
  (K. Narkowicz, "ACES Filmic Tone Mapping Curve", 2016) per channel: a toe, a long shoulder
  that rolls highlights off instead of clipping them. Chosen as the default because it shows a
  dim scene such as ROOM as a photographer would expose it (lit walls, colour bleeding, the
  highlight) where Ward's operator shows it as dim as it is.
* ``exposure``: the same key exposure, linear, clipped at white: what a camera's meter gives.
* ``ward``: Ward's visibility-matching scale factor, below: the display shows what a viewer
  adapted to the real scene would see, so a dim room stays dim.

The AQM (pipeline/frames/perceived.py) always judges with Ward's operator whatever the look chosen:
visibility predictions need the scene's absolute luminances, and a change of look then neither
re-decides segments nor traces photons again (pipeline/run/render.py keeps the look out of the
decision hash).

Ward's operator: Ward's contrast-based scale factor (G. Ward, "A contrast-based scalefactor for
luminance display", Graphics Gems IV, 1994). From Blackwell's threshold-versus-intensity curve
dL(La) = 0.0594 (1.219 + La^0.4)^2.5, matching a just-noticeable difference in the world to one
on the display gives one global scale  L_d = m L_w,  m = [(1.219 + (Ld_max/2)^0.4) /
(1.219 + L_wa^0.4)]^2.5, and the display value is clamp(L_d / Ld_max, 0, 1) encoded with the sRGB
transfer function. Why Ward: one monotone scalar, no iteration, easy to smooth over time, and it
maps visibility thresholds to visibility thresholds, the invariant behind "noise below what a
viewer sees" (§5); histogram methods are image-dependent and flicker.

Adaptation: L_wa is the log-average (geometric mean) luminance of what the camera sees, the "key"
of Ward (1994) and Reinhard et al. (2002): exp(mean log(DELTA + L)) over the pixels of a
low-resolution pass of the frame's own camera rays against its illumination map
(pipeline/frames/camera_paths.py visible_adaptation), pixels that see nothing left out. Occluded surfaces
never count, so a box moving in front of a wall changes L_wa only by what it covers.
Time course: the eye adapts to L_wa(t) exponentially (Durand & Dorsey, "Interactive tone mapping",
EGWR 2000; Pattanaik et al., "Time-dependent visual adaptation for fast realistic image display",
SIGGRAPH 2000), in the discrete form of Krawczyk, Myszkowski & Seidel ("Perceptual effects in
real-time tone mapping", SCCG 2005, §3.1):
    L_a(t) = L_a(t-dt) + (L_wa(t) - L_a(t-dt)) (1 - exp(-dt / tau(L_a))),
    tau(L_a) = sigma(L_a) tau_rod + (1 - sigma(L_a)) tau_cone,  sigma(Y) = 0.04 / (0.04 + Y),
with tau_cone = 0.1 s, tau_rod = 0.4 s and Y in cd/m^2 (sigma is the rods' share of vision). dt is
the time between the frames rendered (the timeline's fps; a frame list's gaps adapt further); the
first frame rendered starts adapted. A frame's L_a reads only L_wa of frames up to itself, so any
worker computes it from the per-frame values in the segment records.
Units: one radiometric radiance unit is ``nits_per_unit`` cd/m^2 (1 by default, docs/03-conventions.md §1).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import numpy.typing as npt

from kernels.colour import luminance
from pipeline.aqm.display import DISPLAYS, FILLS
from pipeline.errors import ConfigError

DELTA = 1e-4  # cd/m^2 floor inside the log-average (Ward 1994; avoids log 0)
OPERATORS = ("filmic", "exposure", "ward")
KEY = 0.18  # middle grey the adaptation luminance is exposed to (Reinhard et al. 2002)
LOOK_FIELDS = ("operator", "exposure")  # what only the displayed look reads, never the AQM


@dataclass(frozen=True, kw_only=True)
class ToneMapping:
    display_max: float = 100.0  # Ld_max, display white in cd/m^2 (Ward 1994)
    nits_per_unit: float = 1.0  # cd/m^2 per radiometric radiance unit
    tau_cone: float = 0.1  # cone adaptation time constant, s (Krawczyk et al. 2005, after Durand & Dorsey 2000)
    tau_rod: float = 0.4  # rod adaptation time constant, s (same sources)
    operator: str = "filmic"  # filmic | exposure | ward (module docstring)
    exposure: float = 0.0  # EV added to the operator's own exposure (a factor 2^EV)
    # Where the frames are watched, for the AQM (§6, pipeline/frames/perceived.py viewing_for): a display
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
        for name in ("tau_cone", "tau_rod"):
            if not getattr(self, name) >= 0:
                raise ConfigError(f"invalid value {getattr(self, name)!r}: must be >= 0", field=name)

    def to_dict(self) -> dict[str, float | str]:
        return asdict(self)


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


def rod_sensitivity(adaptation_nits: float) -> float:
    """sigma(Y) = 0.04 / (0.04 + Y), Y in cd/m^2: the rods' share of vision (Krawczyk et al. 2005, §3.1)."""
    return 0.04 / (0.04 + max(float(adaptation_nits), 0.0))


def adapt_in_time(values: npt.ArrayLike, times: npt.ArrayLike, params: ToneMapping = ToneMapping()) -> np.ndarray:
    """The eye's adaptation luminance L_a at each frame (module docstring, "Time course").

    ``values``: each frame's own L_wa (radiance units) in render order; ``times`` in seconds. The
    first frame starts adapted; each later one moves towards its L_wa by 1 - exp(-dt / tau), tau
    between the cones' and the rods' time constants by the rods' share at the current L_a.
    """
    v = np.asarray(values, dtype=np.float64)
    t = np.asarray(times, dtype=np.float64)
    out = np.empty_like(v)
    for i in range(len(v)):
        if i == 0:
            out[i] = v[i]
            continue
        sigma = rod_sensitivity(out[i - 1] * params.nits_per_unit)
        tau = sigma * params.tau_rod + (1.0 - sigma) * params.tau_cone
        dt = abs(t[i] - t[i - 1])
        alpha = 1.0 if tau == 0 else -np.expm1(-dt / tau)
        out[i] = out[i - 1] + (v[i] - out[i - 1]) * alpha
    return out


def image_adaptation(rgb: np.ndarray, seen: np.ndarray) -> float:
    """L_wa of an image: the log-average luminance (Ward 1994; Reinhard et al. 2002's key) of the
    pixels ``seen`` (what a camera ray hit, or a sky it saw); DELTA when none is."""
    lum = luminance(np.asarray(rgb).reshape(-1, 3))[np.asarray(seen).reshape(-1)]
    return log_average(lum)


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
