"""The emission kernel (emit.cl) equals its NumPy twin; emitted flux matches the lights' power."""
from __future__ import annotations

import numpy as np

from kernels.emit import AREA, DIRECTIONAL, POINT, SKY, SPOT, EmissionTables, EmitCL, emit_reference
from tests.kernels.twin_base import KernelTwinTests


def _tables(rng, kinds=(POINT, SPOT, DIRECTIONAL, AREA), mapped: bool = False) -> EmissionTables:
    """Random emitter tables; ``mapped``: every other directional light has a projection map of a
    few random cells (pipeline/photons/emission.py), the others emit from the whole disk."""
    n_lights, n_tri = 6, 20
    corners = rng.normal(size=(n_tri, 9)).astype(np.float32)
    c = corners.astype(np.float64).reshape(-1, 3, 3)
    nrm = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    kind, index = [], []
    for i in range(n_lights):
        k = kinds[i % len(kinds)]
        kind.append(k)
        index.append(i if k != AREA else rng.integers(0, n_tri))
    flux = rng.random((n_lights, 3)) * 10
    w = flux.mean(1)
    cdf = np.cumsum(w) / w.sum()
    cdf[-1] = 1.0
    dirs = rng.normal(size=(n_lights, 3))
    dirs[0] = [0, 0, -1]  # straight down: the basis' sign switch
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    outer = rng.uniform(0.2, 1.4, n_lights)
    maps = {}
    if mapped:
        light_cells, cell_size, cells = np.zeros((n_lights, 2), np.int64), np.zeros(n_lights), []
        directional = [i for i, k in enumerate(kind) if k == DIRECTIONAL][::2]
        for i in directional:
            n = int(rng.integers(1, 9))
            light_cells[i] = (sum(len(c) for c in cells), n)
            cell_size[i] = rng.uniform(0.05, 0.5)
            cells.append(rng.uniform(-3.0, 3.0, (n, 2)))
        maps = dict(light_cells=light_cells, cell_size=cell_size, cells=np.concatenate(cells))
    return EmissionTables(
        cdf=cdf, prob=np.diff(np.concatenate([[0.0], cdf])), kind=np.array(kind, np.int32),
        index=np.array(index, np.int64), flux=flux, light_pos=rng.normal(size=(n_lights, 3)), light_dir=dirs,
        light_rad=rng.random((n_lights, 3)) * 5, cos_outer=np.cos(outer), cos_inner=np.cos(outer * 0.5),
        corners=corners, normals=nrm, center=rng.normal(size=3), radius=3.0, epsilon=1e-4, **maps)


class TestEmitTwin(KernelTwinTests):
    """``emit8`` against :func:`emit_reference`: origins, directions, weights and emitters to the bit."""

    ALL = (POINT, SPOT, DIRECTIONAL, AREA, SKY)
    # (emitter kinds, photons): each kind alone, then all mixed at 0, 1, 7 (fewer than LANES) and
    # sizes that are not a multiple of LANES x WORK_GROUP = 512
    cases = {"point-100": ((POINT,), 100), "spot-513": ((SPOT,), 513), "directional-100": ((DIRECTIONAL,), 100),
             "area-513": ((AREA,), 513), "sky-100": ((SKY,), 100), "mixed-0": (ALL, 0), "mixed-1": (ALL, 1),
             "mixed-7": (ALL, 7), "mixed-4097": (ALL, 4097),
             "directional-map-513": ((DIRECTIONAL,), 513, True), "mixed-map-4097": (ALL, 4097, True)}

    def make_inputs(self, rng, case):
        kinds, n, *mapped = case
        return _tables(rng, kinds, *mapped), rng.integers(0, 2**40, n).astype(np.int64), (9, 4)

    def device(self, tables, photon, key):
        return EmitCL(tables)(photon, key)

    def twin(self, tables, photon, key):
        return emit_reference(tables, photon, key)


def test_emitted_flux_is_unbiased(rng):
    """Mean photon weight = total flux; directions are unit; spots stay inside their cone."""
    tables = _tables(rng, (POINT, SPOT, DIRECTIONAL, SKY))
    n = 400_000
    origins, dirs, weights, emitter = emit_reference(tables, np.arange(n), (1, 1))
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-6)
    spot = tables.kind[emitter] == SPOT
    light = tables.index[emitter[spot]]
    cos = np.einsum("ij,ij->i", dirs[spot].astype(np.float64), tables.light_dir[light])
    assert (cos >= tables.cos_outer[light] - 1e-6).all()
    # expected flux: point 4 pi I, spot 2 pi I ((1 - ci) + (ci - co) / 3), directional pi R^2 E,
    # a sky half 2 pi x pi R^2 L
    ci, co = tables.cos_inner, tables.cos_outer
    per_kind = {POINT: 4 * np.pi * np.ones_like(ci), SPOT: 2 * np.pi * ((1 - ci) + (ci - co) / 3),
                DIRECTIONAL: np.pi * tables.radius**2 * np.ones_like(ci),
                SKY: 2 * np.pi * np.pi * tables.radius**2 * np.ones_like(ci)}
    expected = sum(tables.light_rad[i] * per_kind[k][i] for i, k in enumerate(tables.kind))
    mean = weights.mean(axis=0)
    se = weights.std(axis=0) / np.sqrt(n)
    assert np.all(np.abs(mean - expected) < 4 * se)


def test_sky_photons_cross_the_disk_into_their_hemisphere(rng):
    """Sky photons travel into the hemisphere about their half's axis, uniformly in solid angle
    (mean cosine 1/2), and start on a disk of radius R facing their direction, 1.05 R upstream."""
    tables = _tables(rng, (SKY,))
    origins, dirs, _, emitter = emit_reference(tables, np.arange(200_000), (2, 7))
    axis = tables.light_dir[tables.index[emitter]]
    d = dirs.astype(np.float64)
    cos = np.einsum("ij,ij->i", d, axis)
    assert cos.min() >= -1e-7 and abs(cos.mean() - 0.5) < 0.005
    rel = origins.astype(np.float64) - tables.center
    along = np.einsum("ij,ij->i", rel, d)
    np.testing.assert_allclose(along, -1.05 * tables.radius, rtol=1e-5)
    across = np.linalg.norm(rel - along[:, None] * d, axis=1)
    assert across.max() <= tables.radius * (1 + 1e-5) and abs((across ** 2).mean() / tables.radius ** 2 - 0.5) < 0.01


def test_projection_map_photons_start_in_their_cells_and_carry_its_flux(rng):
    """A directional light with a projection map starts its photons uniformly in its cells (in the
    disk's basis, 1.05 R upstream) and their mean weight is E times the cells' area."""
    from kernels.sampling import orthonormal_basis

    tables = _tables(rng, (DIRECTIONAL,), mapped=True)
    n = 200_000
    origins, dirs, weights, emitter = emit_reference(tables, np.arange(n), (3, 5))
    light_cells, cell_size, cells = tables.projection()
    light = tables.index[emitter]
    mapped = light_cells[light, 1] > 0
    assert mapped.any() and (~mapped).any()
    for li in np.unique(light[mapped]):
        pick = light == li
        axis = tables.light_dir[li]
        tt, ss = (v[0] for v in orthonormal_basis(axis[None]))
        rel = origins[pick].astype(np.float64) - tables.center
        np.testing.assert_allclose(rel @ axis, -1.05 * tables.radius, atol=1e-4)
        a, b = rel @ tt, rel @ ss
        start, count = light_cells[li]
        h = cell_size[li]
        own = cells[start:start + count]
        inside = ((a[:, None] >= own[None, :, 0] - 1e-4) & (a[:, None] <= own[None, :, 0] + h + 1e-4)
                  & (b[:, None] >= own[None, :, 1] - 1e-4) & (b[:, None] <= own[None, :, 1] + h + 1e-4))
        assert inside.any(axis=1).all()
        expected = tables.light_rad[li] * count * h * h
        k = np.flatnonzero((tables.kind == DIRECTIONAL) & (tables.index == li))[0]
        w = weights[pick] * tables.prob[k]  # the light's flux estimate per photon
        np.testing.assert_allclose(w.mean(axis=0), expected, rtol=1e-12)
