"""The compositor's element lookup kernel (surface.cl) equals its NumPy twin and ElementMesh.locate."""
from __future__ import annotations

import numpy as np
import pytest

from kernels.surface import LookupCL, lookup_reference


@pytest.mark.parametrize("m", [1, 7, 8, 1000, 5003])
@pytest.mark.parametrize("blend", [True, False])
def test_lookup_equals_reference(rng, m, blend):
    n_tri = 40
    tri_n = rng.integers(1, 30, n_tri).astype(np.int32)
    tri_offset = np.concatenate([[0], np.cumsum(tri_n.astype(np.int64) ** 2)[:-1]])
    n_elements = int((tri_n.astype(np.int64) ** 2).sum())
    table = rng.random((n_elements, 3, 3)).astype(np.float32) if blend else None
    tri = rng.integers(0, n_tri, m).astype(np.int32)
    u, v = rng.random(m), rng.random(m)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    u[: min(m, 3)] = [0.0, 1.0, 1.0 + 1e-7][: min(m, 3)]  # corners and float32 spill past the edge
    u, v = u.astype(np.float32), v.astype(np.float32)
    cell, irr = LookupCL(tri_n, tri_offset, table)(tri, u, v)
    ref_cell, ref_irr = lookup_reference(tri_n, tri_offset, table, tri, u, v)
    np.testing.assert_array_equal(cell, ref_cell)
    assert np.all((cell >= tri_offset[tri]) & (cell < tri_offset[tri] + tri_n[tri].astype(np.int64) ** 2))
    if blend:
        np.testing.assert_allclose(irr, ref_irr, rtol=1e-6, atol=1e-7)
    else:
        assert irr is None and ref_irr is None


def test_lookup_matches_element_mesh_locate(tmp_path):
    from pipeline.scene import ElementMesh, Scene
    from pipeline.scene.builtin import write_builtin

    scene = Scene.load(write_builtin("cornell", tmp_path / "c.glb"))
    mesh = ElementMesh.build(scene, 0.1)
    rng = np.random.default_rng(3)
    tri = rng.integers(0, len(mesh.triangle_n), 4000)
    u, v = rng.random(4000), rng.random(4000)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    u, v = u.astype(np.float32), v.astype(np.float32)
    element, _, _ = mesh.locate(tri, u, v)
    cell, _ = LookupCL(mesh.triangle_n, mesh.triangle_offset[:-1], None)(tri, u, v)
    np.testing.assert_array_equal(cell, element)
