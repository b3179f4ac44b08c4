"""The compositor's element lookup kernel (surface.cl) equals its NumPy twin and ElementMesh.locate."""
from __future__ import annotations

import numpy as np

from kernels.surface import LookupCL, lookup_reference
from pipeline.scene import read_scene
from tests.kernels.twin_base import KernelTwinTests


def _lookup_inputs(rng, m, blend):
    """Random element tables of 40 triangles and ``m`` hits on them (corners and float32 spill too)."""
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
    return tri_n, tri_offset, table, tri, u.astype(np.float32), v.astype(np.float32)


class TestLookupTwin(KernelTwinTests):
    """``lookup8`` against :func:`lookup_reference`: the same elements, irradiance within 1e-6."""

    # (hits, blend): none, one, fewer than LANES, exactly LANES, not a multiple of LANES x WORK_GROUP
    cases = {f"{m}-{'blend' if blend else 'ids'}": (m, blend) for m in (0, 1, 7, 8, 1000, 5003)
             for blend in (True, False)}

    def make_inputs(self, rng, case):
        return _lookup_inputs(rng, *case)

    def device(self, tri_n, tri_offset, table, tri, u, v):
        return LookupCL(tri_n, tri_offset, table)(tri, u, v)

    def twin(self, tri_n, tri_offset, table, tri, u, v):
        return lookup_reference(tri_n, tri_offset, table, tri, u, v)

    def rule(self, name, want):
        return (0.0, 0.0) if name == "0" else (1e-6, 1e-7)  # element ids exact, irradiance close


def test_elements_stay_in_their_triangle(rng):
    tri_n, tri_offset, table, tri, u, v = _lookup_inputs(rng, 5003, False)
    cell, irr = lookup_reference(tri_n, tri_offset, table, tri, u, v)
    assert irr is None
    assert np.all((cell >= tri_offset[tri]) & (cell < tri_offset[tri] + tri_n[tri].astype(np.int64) ** 2))


def test_lookup_matches_element_mesh_locate(tmp_path):
    from pipeline.scene import ElementMesh
    from pipeline.scene.builtin import write_builtin

    scene = read_scene(write_builtin("cornell", tmp_path / "c.glb"))
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
