"""vertex_irradiance (dept.md §1.2): exact splatting on a hand-made mesh, and unbiasedness on a plane."""
from __future__ import annotations

import numpy as np

from workers.reconstruct import vertex_irradiance

# Two elements sharing an edge: the unit square split along its diagonal
VERTS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
ELEMS = np.array([[0, 1, 2], [0, 2, 3]])


def _vertex_areas():
    p = VERTS[ELEMS]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    return np.bincount(ELEMS.ravel(), weights=np.repeat(area / 3, 3), minlength=4)


def test_one_hit_splats_its_barycentrics():
    areas = _vertex_areas()
    e = vertex_irradiance(np.array([1]), np.array([0.25]), np.array([0.5]), np.array([[4.0, 8.0, 0.0]]),
                          ELEMS, areas, 2)
    want = np.zeros((4, 3))
    want[[0, 2, 3], :] = np.array([0.25, 0.25, 0.5])[:, None] * [4.0, 8.0, 0.0]
    want /= 2 * areas[:, None]
    np.testing.assert_allclose(e, want, rtol=1e-15)
    assert e.dtype == np.float64 and e.shape == (4, 3)


def test_fixed_point_barycentrics_and_zero_area_vertices():
    areas = np.append(_vertex_areas(), 0.0)  # a fifth vertex no element uses
    b = np.array([65535 // 2], np.uint16)
    e = vertex_irradiance(np.array([0]), b, b, np.ones((1, 3), np.float32), ELEMS, areas, 1)
    assert np.isfinite(e).all() and (e[4] == 0).all()
    np.testing.assert_allclose(e[:, 0].dot(areas), 1.0, rtol=1e-12)  # energy is conserved


def test_uniform_photons_give_constant_irradiance(rng):
    n, flux = 200_000, 3.0  # flux spread uniformly over the unit square: E = 3 everywhere
    x = rng.random((n, 2))
    lower = x[:, 0] >= x[:, 1]  # element 0: (0,0),(1,0),(1,1)
    b1 = np.where(lower, x[:, 0] - x[:, 1], x[:, 0])
    b2 = np.where(lower, x[:, 1], x[:, 1] - x[:, 0])
    energy = np.full((n, 3), flux)  # weight = flux x N / N
    e = vertex_irradiance(np.where(lower, 0, 1), b1, b2, energy, ELEMS, _vertex_areas(), n)
    np.testing.assert_allclose(e, flux, rtol=0.02)
