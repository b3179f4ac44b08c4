"""Display and viewing model: linear RGB -> luminance in cd/m^2, pixels per degree, resampling.

The AQM works on the luminance a viewer sees on a stated display (Daly 1993 takes cd/m^2 as input),
so a rendering's linear Rec.709 value 1.0 is mapped to the display's peak white and values above it
are clipped, as a monitor does. Spatial frequencies need pixels per degree: of the display, of the
frame as it is shown (full screen by default), and of the AQM's 256-pixel image (§6 of the paper),
all derived here by pure functions (docs/08-aqm.md §6).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from kernels.colour import LUMA  # Rec. 709 / sRGB luminance weights (ITU-R BT.709-6)

from ..errors import LoomError

INCH = 0.0254  # metres
FILLS = ("full_screen", "native")


def pixels_per_degree(pixel_m: float, distance_m: float) -> float:
    """Pixels per degree at the centre of a screen of pixel pitch ``pixel_m`` seen from ``distance_m``:
    1 / (2 atan(pitch / (2 d)) in degrees) (docs/08-aqm.md §6; ColorVideoVDP and FLIP use the same)."""
    return 1.0 / math.degrees(2.0 * math.atan(pixel_m / (2.0 * distance_m)))


def width_from_diagonal(diagonal_in: float, resolution: tuple[int, int]) -> float:
    """Width in metres of a display of ``diagonal_in`` inches with square pixels."""
    w, h = resolution
    return diagonal_in * INCH * w / math.hypot(w, h)


@dataclass(frozen=True)
class ViewingConditions:
    """How the frames are watched; every frequency- and luminance-dependent stage derives from it.

    Geometry: a display ``display_width_m`` wide with ``resolution`` pixels, seen from
    ``viewing_distance_m``. ``fill`` says how a frame is shown on it: "full_screen" (the default, how an
    animation is watched) scales the frame to fill the display with its aspect kept, "native" shows one
    frame pixel per display pixel. The default display is ColorVideoVDP's "standard_fhd" geometry (a
    24-inch 16:9 1920x1080 monitor from 0.6 m, 37.9 pixels per degree) with peak white 100 cd/m^2 (the
    reference white of an sRGB/Rec.709 monitor, docs/08-aqm.md §1 [decision]) and black 0.1 cd/m^2 (1000:1);
    :meth:`named` gives ColorVideoVDP's displays as they are defined there.
    """

    display_width_m: float = 0.531
    resolution: tuple[int, int] = (1920, 1080)  # (width, height) in display pixels
    viewing_distance_m: float = 0.6
    peak_luminance: float = 100.0  # cd/m^2 of linear value 1.0
    black_level: float = 0.1  # cd/m^2 of linear value 0.0
    fill: str = "full_screen"  # one of FILLS
    name: str = "default (standard_fhd geometry)"

    def __post_init__(self) -> None:
        checks = {
            "display_width_m": _finite(self.display_width_m) and self.display_width_m > 0,
            "resolution": len(self.resolution) == 2 and all(int(r) == r and r > 0 for r in self.resolution),
            "viewing_distance_m": _finite(self.viewing_distance_m) and self.viewing_distance_m > 0,
            "peak_luminance": _finite(self.peak_luminance) and self.peak_luminance > 0,
            "black_level": _finite(self.black_level) and 0 <= self.black_level < self.peak_luminance,
            "fill": self.fill in FILLS,
        }
        for name, ok in checks.items():
            if not ok:
                raise LoomError(f"invalid value {getattr(self, name)!r}", field=f"viewing.{name}")

    @property
    def ppd(self) -> float:
        """Pixels per degree of the display's own pixels at the centre of the screen."""
        return pixels_per_degree(self.display_width_m / self.resolution[0], self.viewing_distance_m)

    def frame_scale(self, frame_shape: tuple[int, int]) -> float:
        """Display pixels per frame pixel: the largest that fits the display full screen, 1 for native."""
        if self.fill == "native":
            return 1.0
        h, w = frame_shape[:2]
        return min(self.resolution[0] / w, self.resolution[1] / h)

    def frame_ppd(self, frame_shape: tuple[int, int]) -> float:
        """Pixels per degree of a frame of ``frame_shape`` (H, W) as it is shown."""
        pitch = self.display_width_m / self.resolution[0] * self.frame_scale(frame_shape)
        return pixels_per_degree(pitch, self.viewing_distance_m)

    @classmethod
    def named(cls, name: str, **fields: float | str | tuple[int, int]) -> ViewingConditions:
        """ColorVideoVDP's display ``name`` (pycvvdp display_models.json): size, resolution, distance,
        peak luminance and contrast (black = peak / contrast); ``fields`` override any of them."""
        if name not in DISPLAYS:
            raise LoomError(f"unknown display {name!r}; known: {', '.join(DISPLAYS)}", field="viewing.display")
        diagonal, resolution, distance, peak, contrast = DISPLAYS[name]
        base = {"display_width_m": width_from_diagonal(diagonal, resolution), "resolution": resolution,
                "viewing_distance_m": distance, "peak_luminance": peak, "black_level": peak / contrast,
                "name": name}
        changed = sorted(k for k, v in fields.items() if k != "name" and base.get(k) != v and k != "fill")
        if changed:
            base["name"] = f"{name} with {', '.join(changed)} changed"
        return cls(**{**base, **fields})

    @classmethod
    def for_ppd(cls, ppd: float, **fields: float | str | tuple[int, int]) -> ViewingConditions:
        """Native-pixel conditions with the viewing distance chosen so the display has ``ppd`` pixels per degree."""
        base = cls(**{"fill": "native", "name": f"{ppd:g} px/deg", **fields})
        pixel = base.display_width_m / base.resolution[0]
        distance = pixel / (2.0 * math.tan(math.radians(1.0 / ppd) / 2.0))
        return replace(base, viewing_distance_m=distance)


# ColorVideoVDP's display models (Mantiuk et al. 2024, pycvvdp/vvdp_data/display_models.json):
# name: (diagonal in inches, resolution, viewing distance in m, peak cd/m^2, contrast)
DISPLAYS: dict[str, tuple[float, tuple[int, int], float, float, float]] = {
    "standard_fhd": (24.0, (1920, 1080), 0.6, 200.0, 1000.0),
    "standard_4k": (30.0, (3840, 2160), 0.7472, 200.0, 1000.0),
}


@dataclass(frozen=True)
class AQMGeometry:
    """Where the AQM looks (§6): a frame resampled to ``shape`` with the observer's distance scaled so
    the visual angles stay those of the frame as shown."""

    frame_shape: tuple[int, int]
    frame_ppd: float  # pixels per degree of the frame as shown
    shape: tuple[int, int]  # (H, W) the AQM works at
    ppd: float  # pixels per degree of the AQM image
    scaled_distance_m: float  # §6's observer distance: the AQM image's pixels, at the display's pitch, at ppd
    image_area_deg2: float  # Daly's i^2: the image's area in square degrees

    def describe(self, viewing: ViewingConditions) -> str:
        """One line for a render's log and report."""
        h, w = self.frame_shape
        return (f"viewing {viewing.name}: {viewing.resolution[0]}x{viewing.resolution[1]} display "
                f"{viewing.display_width_m:.3f} m wide at {viewing.viewing_distance_m:.2f} m, "
                f"{viewing.peak_luminance:g} cd/m^2, {viewing.fill.replace('_', ' ')}; frame {w}x{h} at "
                f"{self.frame_ppd:.1f} px/deg; AQM {self.shape[1]}x{self.shape[0]} at {self.ppd:.2f} px/deg "
                f"(observer at {self.scaled_distance_m:.3f} m, §6)")


def aqm_geometry(viewing: ViewingConditions, frame_shape: tuple[int, int], aqm_size: int) -> AQMGeometry:
    """The AQM's image size and pixels per degree for frames of ``frame_shape`` (H, W) (§6).

    The frame is resampled so its longer side is ``aqm_size`` (never enlarged); its pixels per degree
    scale by the same factor, which is the paper's "proportionally reduce the distance of the observer":
    the scaled distance is the one at which the AQM image, at the display's pixel pitch, has that ppd.
    """
    frame_shape = (int(frame_shape[0]), int(frame_shape[1]))
    shape = aqm_shape(frame_shape, aqm_size)
    frame_ppd = viewing.frame_ppd(frame_shape)
    ppd = frame_ppd * math.sqrt(shape[0] * shape[1] / (frame_shape[0] * frame_shape[1]))
    pitch = viewing.display_width_m / viewing.resolution[0]
    scaled = pitch / (2.0 * math.tan(math.radians(1.0 / ppd) / 2.0))
    return AQMGeometry(frame_shape, frame_ppd, shape, ppd, scaled, (shape[0] / ppd) * (shape[1] / ppd))


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and math.isfinite(x)


def check_image(image: npt.ArrayLike, name: str) -> np.ndarray:
    """Validate an input image (H, W) or (H, W, C>=3) and return it as float64; LoomError otherwise."""
    arr = np.asarray(image)
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] not in (1, 3, 4)) or min(arr.shape[:2]) < 8:
        raise LoomError(f"expected an image of shape (H, W) or (H, W, 1|3|4) with H, W >= 8, got {arr.shape}",
                        path=name, field="shape")
    if not np.issubdtype(arr.dtype, np.number):
        raise LoomError(f"expected numbers, got dtype {arr.dtype}", path=name, field="dtype")
    arr = arr.astype(np.float64, copy=False)
    bad = ~np.isfinite(arr)
    if bad.any():
        y, x = np.argwhere(bad)[0][:2]
        raise LoomError(f"{int(bad.sum())} NaN or Inf value(s), first at pixel (x={x}, y={y})",
                        path=name, field="pixels")
    return arr


def relative_luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec. 709 relative luminance Y of linear RGB (H, W, 3|4); a 2-D or 1-channel input is taken as Y."""
    if rgb.ndim == 2:
        return rgb
    if rgb.shape[2] == 1:
        return rgb[..., 0]
    r, g, b = LUMA
    return r * rgb[..., 0] + g * rgb[..., 1] + b * rgb[..., 2]


def display_luminance(y: np.ndarray, viewing: ViewingConditions, name: str = "image") -> np.ndarray:
    """Luminance in cd/m^2 shown for relative luminance ``y``: black + (peak - black) * clip(y, 0, 1).

    Negative input is an error, not clipped: a linear rendering never has negative light, so it
    signals a broken file or pipeline.
    """
    check_luminance(y, name)
    return viewing.black_level + (viewing.peak_luminance - viewing.black_level) * np.minimum(y, 1.0)


def check_luminance(lum: np.ndarray, name: str) -> None:
    """LoomError if any luminance is negative (reports the count and the first pixel)."""
    neg = lum < 0
    if neg.any():
        y, x = np.argwhere(neg)[0]
        raise LoomError(f"{int(neg.sum())} negative luminance value(s), first at pixel (x={x}, y={y})",
                        path=name, field="luminance")


def _area_matrix(n_in: int, n_out: int) -> np.ndarray:
    """(n_out, n_in) matrix averaging the input cells each output cell covers (box/area resampling)."""
    edges = np.linspace(0.0, n_in, n_out + 1)
    lo, hi = edges[:-1, None], edges[1:, None]
    cells = np.arange(n_in)[None, :]
    overlap = np.clip(np.minimum(hi, cells + 1) - np.maximum(lo, cells), 0.0, None)
    return overlap / overlap.sum(axis=1, keepdims=True)


def aqm_shape(shape: tuple[int, int], aqm_size: int) -> tuple[int, int]:
    """Shape the AQM works at: the longer side scaled down to ``aqm_size``, aspect kept (never enlarged)."""
    h, w = shape
    scale = min(1.0, aqm_size / max(h, w))
    return max(1, round(h * scale)), max(1, round(w * scale))


def resample(image: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Area-average ``image`` (H, W[, C]) to ``shape`` (§6 of the paper: AQM inputs are 256x256).

    Box integration is exact for integer factors and never rings; the identity is returned as is.
    """
    if image.shape[:2] == tuple(shape):
        return image
    rows = _area_matrix(image.shape[0], shape[0])
    cols = _area_matrix(image.shape[1], shape[1])
    if image.ndim == 2:
        return rows @ image @ cols.T
    return np.einsum("ij,jkc,lk->ilc", rows, image, cols, optimize=True)
