"""The projection map of directional lights and the absorption at single-sided backs, on synthetic
geometry (a stand-in ray caster: no Embree)."""
from __future__ import annotations

import numpy as np

from pipeline.photons.emission import projection_map
from pipeline.photons.sidedness import absorb_back_hits


class _Skylight:
    """Triangle 0: a roof at y = 0 facing down with a hole |x|, |z| < 0.5; triangle 1: a floor at
    y = -2 facing up; triangle 2: a free-standing double-sided board over x in [3, 4], facing down."""

    normals = np.array([[0.0, -1.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])

    def intersect(self, origins, directions):
        x, z = origins[:, 0], origins[:, 2]
        tri = np.where((np.abs(x) < 0.5) & (np.abs(z) < 0.5), 1, 0)
        tri = np.where((x >= 3) & (x <= 4) & (np.abs(z) < 0.5), 2, tri)
        tri = np.where((np.abs(x) > 5) | (np.abs(z) > 5), -1, tri)
        n = len(origins)
        return tri.astype(np.int32), np.zeros(n, np.float32), np.zeros(n, np.float32), np.ones(n, np.float32)


def _covered(corners, h, x, z):
    """Which points (x, z) lie in a cell; the sun travels along -y, whose basis is checked below."""
    from kernels.sampling import orthonormal_basis

    tt, ss = (v[0] for v in orthonormal_basis(np.array([[0.0, -1.0, 0.0]])))
    p = np.stack([x, np.zeros_like(x), z], axis=1)
    a, b = p @ tt, p @ ss
    inside = ((a[:, None] >= corners[None, :, 0]) & (a[:, None] < corners[None, :, 0] + h)
              & (b[:, None] >= corners[None, :, 1]) & (b[:, None] < corners[None, :, 1] + h))
    return inside.any(axis=1)


def test_projection_map_keeps_the_hole_and_double_sided_surfaces_and_drops_single_sided_backs(rng):
    one_sided = np.array([True, True, False])
    corners, h = projection_map(_Skylight(), np.array([0.0, -1.0, 0.0]), np.zeros(3), 8.0, one_sided, grid=128)
    x, z = rng.uniform(-0.5, 0.5, 2000), rng.uniform(-0.5, 0.5, 2000)
    assert _covered(corners, h, x, z).all()  # every point of the hole, edges included
    assert _covered(corners, h, rng.uniform(3, 4, 500), rng.uniform(-0.5, 0.5, 500)).all()  # the board
    far = rng.uniform(-4.5, -1.0, 500)
    assert not _covered(corners, h, far, far).any()  # the roof's back, away from the hole
    area = len(corners) * h * h
    assert 2.0 < area < 2.0 * (1 + 4 * 4 * h)  # the hole and the board and a margin of one cell


def test_projection_map_of_a_light_that_misses_everything_is_the_whole_square():
    class Nothing(_Skylight):
        def intersect(self, origins, directions):
            tri, u, v, t = super().intersect(origins, directions)
            return np.full_like(tri, -1), u, v, t

    corners, h = projection_map(Nothing(), np.array([0.0, -1.0, 0.0]), np.zeros(3), 1.0, None, grid=16)
    assert len(corners) == 16 * 16 and np.isclose(h, 2.0 / 16)


def test_back_hits_on_single_sided_triangles_become_misses():
    normals = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    one_sided = np.array([True, False])
    tri = np.array([0, 0, 1, 1, -1], np.int32)
    dirs = np.array([[0, 0, -1], [0, 0, 1], [0, 0, 1], [0, 0, -1], [0, 0, 1]], np.float32)
    out = absorb_back_hits(tri, dirs, normals, one_sided)
    np.testing.assert_array_equal(out, [0, -1, 1, 1, -1])  # only the back of the single-sided one
    assert out.dtype == tri.dtype
    assert absorb_back_hits(tri, dirs, normals, None) is tri
