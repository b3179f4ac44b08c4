"""How a photon hit record encodes its element, kind and barycentrics: the one owner of these bits.

``scatter`` writes them, ``gather`` reads them and the store (pipeline/store/records.py) checks and
orders them; the OpenCL sources get them as build options (:data:`BUILD_DEFINES`, passed by
kernels/context.py), so no ``.cl`` file holds a copy.
"""
from __future__ import annotations

import numpy as np

ELEMENT_BITS = 30
ELEMENT_MASK = (1 << ELEMENT_BITS) - 1  # key bits 0-29: element id
PARITY_BIT = np.uint32(1 << ELEMENT_BITS)  # key bit 30: photon index is odd
DIRECT_BIT = np.uint32(1 << (ELEMENT_BITS + 1))  # key bit 31: first hit from a light
BARY_SCALE = 65535  # b1, b2 are u16 fixed point b * BARY_SCALE; b0 = 1 - b1 - b2

BUILD_DEFINES = {
    "PARITY_BIT": f"{int(PARITY_BIT):#x}u",
    "DIRECT_BIT": f"{int(DIRECT_BIT):#x}u",
    "BARY_SCALE": f"{float(BARY_SCALE)!r}",
}
