"""Display and viewing model: linear RGB -> luminance in cd/m^2, pixels per degree, resampling.

The AQM works on the luminance a viewer sees on a stated display (Daly 1993 takes cd/m^2 as input),
so a rendering's linear Rec.709 value 1.0 is mapped to the display's peak white and values above it
are clipped, as a monitor does. Spatial frequencies need pixels per degree, derived here once from
the display width, its horizontal resolution and the viewing distance (docs/aqm.md §6).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from kernels.colour import LUMA  # Rec. 709 / sRGB luminance weights (ITU-R BT.709-6)

from ..errors import LoomError


@dataclass(frozen=True)
class ViewingConditions:
    """How the frames are watched; every frequency- and luminance-dependent stage derives from it.

    Defaults: a 24-inch 16:9 LCD (0.531 m wide, 1920x1080 pixels) watched from 0.6 m, which gives
    37.9 pixels per degree at the display's native resolution; peak white 100 cd/m^2 (the usual
    reference white of an sRGB/Rec.709 monitor, docs/aqm.md §1 [decision]) and a black level of
    0.1 cd/m^2 (a 1000:1 panel). A frame is assumed shown at one image pixel per display pixel.
    """

    display_width_m: float = 0.531
    resolution: tuple[int, int] = (1920, 1080)  # (width, height) in display pixels
    viewing_distance_m: float = 0.6
    peak_luminance: float = 100.0  # cd/m^2 of linear value 1.0
    black_level: float = 0.1  # cd/m^2 of linear value 0.0

    def __post_init__(self) -> None:
        checks = {
            "display_width_m": _finite(self.display_width_m) and self.display_width_m > 0,
            "resolution": len(self.resolution) == 2 and all(int(r) == r and r > 0 for r in self.resolution),
            "viewing_distance_m": _finite(self.viewing_distance_m) and self.viewing_distance_m > 0,
            "peak_luminance": _finite(self.peak_luminance) and self.peak_luminance > 0,
            "black_level": _finite(self.black_level) and 0 <= self.black_level < self.peak_luminance,
        }
        for name, ok in checks.items():
            if not ok:
                raise LoomError(f"invalid value {getattr(self, name)!r}", field=f"viewing.{name}")

    @property
    def ppd(self) -> float:
        """Pixels per degree at the centre of the screen (exact form of docs/aqm.md §6)."""
        pixel = self.display_width_m / self.resolution[0]
        return 1.0 / math.degrees(2.0 * math.atan(pixel / (2.0 * self.viewing_distance_m)))

    @classmethod
    def for_ppd(cls, ppd: float, **fields: float | tuple[int, int]) -> ViewingConditions:
        """Conditions with the viewing distance chosen so the display has ``ppd`` pixels per degree."""
        base = cls(**fields)
        pixel = base.display_width_m / base.resolution[0]
        distance = pixel / (2.0 * math.tan(math.radians(1.0 / ppd) / 2.0))
        return replace(base, viewing_distance_m=distance)


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
