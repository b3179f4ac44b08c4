"""Where a hit lands among the elements of a source triangle split n x n (pure NumPy).

The element mesh (pipeline/scene/elements.py) numbers its cells with these indices, and the
bounce (kernels/scatter.py) and surface lookup (kernels/surface.py) locate hits with
:func:`locate_in_triangles`; ``locate8`` in kernels/lanes.cl is the same arithmetic on the device.
"""
from __future__ import annotations

import numpy as np
import numpy.typing as npt


def up_index(a: int | np.ndarray, b: int | np.ndarray, n: int | np.ndarray) -> int | np.ndarray:
    """Cell-local index of up cell (a, b) in a triangle split n x n."""
    return a * n - a * (a - 1) // 2 + b


def down_index(a: int | np.ndarray, b: int | np.ndarray, n: int | np.ndarray) -> int | np.ndarray:
    """Cell-local index of down cell (a, b)."""
    return n * (n + 1) // 2 + a * (n - 1) - a * (a - 1) // 2 + b


def locate_in_triangles(triangle_n: npt.ArrayLike, triangle_offset: npt.ArrayLike, triangle: npt.ArrayLike,
                        u: npt.ArrayLike, v: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(element, b1, b2) of hits at Embree barycentrics (u, v) on source triangles split n x n
    (pipeline/scene/elements.py describes the layout): the cell containing (u n, v n), up or down,
    and the hit's barycentrics of the cell's vertices 1 and 2, clipped to the cell. The OpenCL
    kernels use the same arithmetic (``locate8`` in kernels/lanes.cl)."""
    triangle = np.asarray(triangle, dtype=np.int64)
    n = np.asarray(triangle_n)[triangle].astype(np.int64)
    x = np.clip(np.asarray(u, np.float64), 0.0, 1.0) * n
    y = np.clip(np.asarray(v, np.float64), 0.0, 1.0) * n
    a = np.clip(np.floor(x).astype(np.int64), 0, n - 1)
    b = np.clip(np.floor(y).astype(np.int64), 0, n - 1 - a)
    fx = x - a
    fy = y - b
    up = (fx + fy <= 1.0) | (a + b >= n - 1)
    local = np.where(up, up_index(a, b, n), down_index(a, b, np.maximum(n, 1)))
    b1 = np.clip(np.where(up, fx, fx + fy - 1.0), 0.0, 1.0)
    b2 = np.clip(np.where(up, fy, 1.0 - fx), 0.0, 1.0 - b1)
    return (np.asarray(triangle_offset)[triangle] + local).astype(np.int64), b1, b2
