"""Directions about an axis, the NumPy twin of ``kernels/sampling.cl`` (same operations, same order,
so the kernels and their twins agree to the bit)."""
from __future__ import annotations

import numpy as np


def orthonormal_basis(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tangents (t, s) of unit vectors z (n, 3): Duff et al., JCGT 6(1), 2017."""
    sgn = np.where(z[:, 2] >= 0, 1.0, -1.0)
    ia = -1.0 / (sgn + z[:, 2])
    ib = z[:, 0] * z[:, 1] * ia
    t = np.stack([1.0 + sgn * z[:, 0] * z[:, 0] * ia, sgn * ib, -sgn * z[:, 0]], 1)
    s = np.stack([ib, sgn + z[:, 1] * z[:, 1] * ia, -z[:, 1]], 1)
    return t, s


def around(z: np.ndarray, cos_t: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Directions at polar angle acos(cos_t) and azimuth phi about unit axes z (n, 3)."""
    t, s = orthonormal_basis(z)
    sin_t = np.sqrt(np.minimum(np.maximum(1.0 - cos_t * cos_t, 0.0), 1.0))
    cp, sp = np.cos(phi), np.sin(phi)
    return t * (sin_t * cp)[:, None] + s * (sin_t * sp)[:, None] + z * cos_t[:, None]
