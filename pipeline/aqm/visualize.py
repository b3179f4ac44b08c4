"""M_AQM as a picture, like Fig. 3d of the paper: red where a difference is predicted visible, over grey A."""
from __future__ import annotations

import numpy as np

from .display import relative_luminance


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """sRGB transfer function (IEC 61966-2-1) of linear values clipped to [0, 1]."""
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def upsample_nearest(values: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Nearest-neighbour resampling of a 2-D map to ``shape`` (the AQM map back to frame size)."""
    rows = np.minimum((np.arange(shape[0]) + 0.5) * values.shape[0] / shape[0], values.shape[0] - 1).astype(int)
    cols = np.minimum((np.arange(shape[1]) + 0.5) * values.shape[1] / shape[1], values.shape[1] - 1).astype(int)
    return values[np.ix_(rows, cols)]


def difference_picture(image_a: np.ndarray, visible: np.ndarray) -> np.ndarray:
    """8-bit sRGB picture (H, W, 3) of A in grey with pixels in ``visible`` (any resolution) in red."""
    grey = srgb_encode(relative_luminance(np.asarray(image_a, dtype=np.float64)))
    rgb = np.repeat(grey[..., None], 3, axis=2)
    mask = upsample_nearest(visible, grey.shape)
    rgb[mask] = (1.0, 0.0, 0.0)
    return np.round(rgb * 255.0).astype(np.uint8)
