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


PIO2_HI = 1.57079632673412561417e+00
PIO2_LO = 6.07710050650619224932e-11
TWO_OVER_PI = 6.36619772367581382433e-01
_S = (-1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04,
      2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10)
_C = (4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05,
      -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11)


def sincos_poly(phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """sin and cos from fdlibm's kernel polynomials (__kernel_sin, __kernel_cos) after a Cody-Waite
    reduction by pi/2: the operations of ``sincos8`` in scatter.cl in the same order, so kernel and
    twin agree to the bit without depending on two libm implementations (about 1 ulp accurate)."""
    q = np.rint(phi * TWO_OVER_PI)
    r = (phi - q * PIO2_HI) - q * PIO2_LO
    z = r * r
    sr = r + (z * r) * (_S[0] + z * (_S[1] + z * (_S[2] + z * (_S[3] + z * (_S[4] + z * _S[5])))))
    cr = 1.0 - (0.5 * z - z * (z * (_C[0] + z * (_C[1] + z * (_C[2] + z * (_C[3] + z * (_C[4] + z * _C[5])))))))
    quadrant = q.astype(np.int64) & 3
    return np.choose(quadrant, [sr, cr, -sr, -cr]), np.choose(quadrant, [cr, -sr, -cr, sr])


def around(z: np.ndarray, cos_t: np.ndarray, phi: np.ndarray, *, polynomial: bool = False) -> np.ndarray:
    """Directions at polar angle acos(cos_t) and azimuth phi about unit axes z (n, 3); with
    ``polynomial`` the sine and cosine come from :func:`sincos_poly` (the bounce kernel's)."""
    t, s = orthonormal_basis(z)
    sin_t = np.sqrt(np.minimum(np.maximum(1.0 - cos_t * cos_t, 0.0), 1.0))
    sp, cp = sincos_poly(phi) if polynomial else (np.sin(phi), np.cos(phi))
    return t * (sin_t * cp)[:, None] + s * (sin_t * sp)[:, None] + z * cos_t[:, None]
