"""vertex_irradiance (docs/05-estimators.md §1.2): exact splatting on a hand-made mesh, and unbiasedness on a plane."""
from __future__ import annotations

import numpy as np

from pipeline.collection.estimators import vertex_irradiance

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


def test_records_irradiance_is_vertex_irradiance_bit_for_bit(rng):
    """The direct estimate's fast path (integer picks, one product) gives vertex_irradiance's bits."""
    from types import SimpleNamespace

    from pipeline.collection.estimators import records_irradiance

    n_elements, n_vertices = 40, 30
    elems = rng.integers(0, n_vertices, (n_elements, 3))
    areas = rng.random(n_vertices)
    areas[3] = 0.0
    n = 5000
    b1 = rng.integers(0, 30000, n).astype(np.uint16)
    records = SimpleNamespace(element=rng.integers(0, n_elements, n).astype(np.uint32), b1=b1,
                              b2=(rng.integers(0, 30000, n)).astype(np.uint16),
                              energy=rng.random((n, 3)).astype(np.float32), photons_emitted=1234)
    select = rng.random(n) < 0.4
    for sel in (select, ~select, np.zeros(n, bool)):
        got = records_irradiance(records, sel, elems, areas)
        want = vertex_irradiance(records.element[sel], records.b1[sel], records.b2[sel], records.energy[sel],
                                 elems, areas, records.photons_emitted)
        assert got.dtype == want.dtype and np.array_equal(got, want)
