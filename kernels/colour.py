"""Rec. 709 luminance of linear RGB (ITU-R BT.709): the one owner of the weights.

The gather's variance term, the adaptive filter, tone mapping (pipeline/frames/tonemap.py) and the display
model (pipeline/aqm/display.py) all weigh colour by them; the OpenCL sources get them as the
build options of :data:`BUILD_DEFINES` (kernels/context.py).
"""
from __future__ import annotations

import numpy as np

LUMA = (0.2126, 0.7152, 0.0722)  # Y = LUMA . (R, G, B)

BUILD_DEFINES = {f"LUMA_{c}": repr(w) for c, w in zip("RGB", LUMA)}


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec.709 luminance of linear RGB (..., 3)."""
    return np.asarray(rgb, dtype=np.float64) @ np.asarray(LUMA)
