"""Rec. 709 luminance of linear RGB (ITU-R BT.709): the one owner of the weights.

The gather's variance term, the adaptive filter, tone mapping (pipeline/tonemap.py) and the display
model (pipeline/aqm/display.py) all weigh colour by them; the OpenCL sources get them as the
build options of :data:`BUILD_DEFINES` (kernels/context.py).
"""
from __future__ import annotations

LUMA = (0.2126, 0.7152, 0.0722)  # Y = LUMA . (R, G, B)

BUILD_DEFINES = {f"LUMA_{c}": repr(w) for c, w in zip("RGB", LUMA)}
