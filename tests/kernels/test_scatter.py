"""The photon bounce kernel (scatter.cl) equals its NumPy twin on random and adversarial hits."""
from __future__ import annotations

import numpy as np
import pytest

from kernels.scatter import DIRECT_BIT, PARITY_BIT, Hits, ScatterCL, SceneTables, scatter_reference
from tests.kernels.twin_base import KernelTwinTests


def _tables(rng, n_tri=50, kinds=(0, 1, 2, 3)) -> SceneTables:
    corners = rng.normal(size=(n_tri, 9)).astype(np.float32)
    c = corners.astype(np.float64).reshape(-1, 3, 3)
    nrm = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    n_mat = 6
    albedo = rng.random((n_mat, 3))
    albedo[0] = 0.0  # a black material: Russian roulette always ends the path
    albedo[1] = 1.0
    return SceneTables(corners=corners, normals=nrm, tri_mat=rng.integers(0, n_mat, n_tri).astype(np.int32),
                       tri_n=rng.integers(1, 40, n_tri).astype(np.int32),
                       tri_offset=np.concatenate([[0], np.cumsum(rng.integers(1, 1600, n_tri - 1))]).astype(np.int64),
                       albedo=albedo, kind=np.array([kinds[i % len(kinds)] for i in range(n_mat)], np.int32),
                       exponent=np.array([1.0, 2.0, 10.0, 100.0, 1e4, 0.5]), epsilon=1e-4,
                       ior=np.array([1.5, 1.0, 1.33, 1.5, 2.4, 1.7]))


def _hits(rng, tables, m) -> Hits:
    tri = rng.integers(0, len(tables.tri_mat), m).astype(np.int32)
    u, v = rng.random(m), rng.random(m)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    # adversarial barycentrics: corners, edges, and the float32 rounding just outside
    edge_u = np.array([0, 1, 0, 0.5, 1 + 1e-7, 0])[:m]
    edge_v = np.array([0, 0, 1, 0.5, 0, 1 + 1e-7])[:m]
    u[: len(edge_u)], v[: len(edge_v)] = edge_u, edge_v
    d = rng.normal(size=(m, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    photon = rng.integers(0, 2**40, m)
    photon[: min(m, 2)] = [0, 2**33 + 1][: min(m, 2)]
    return Hits(tri, u.astype(np.float32), v.astype(np.float32), d.astype(np.float32),
                rng.random((m, 3)) * 10.0, photon.astype(np.int64))


class TestScatterTwin(KernelTwinTests):
    """``scatter8`` against :func:`scatter_reference`: keys, barycentrics, energies and flags to the
    bit, origins, directions and weights within 1e-6."""

    # (hits, depth, per-hit textures and shading normals): none, one, fewer than LANES, one short of
    # and exactly WORK_GROUP, not a multiple of LANES x WORK_GROUP
    cases = {"0": (0, 0, False), "1-d0": (1, 0, False), "7-d1": (7, 1, False), "63-d7": (63, 7, False),
             "64-d0": (64, 0, False), "1000-d1": (1000, 1, False), "5000-d7": (5000, 7, False),
             "textured-1-d0": (1, 0, True), "textured-64-d3": (64, 3, True), "textured-4000-d0": (4000, 0, True),
             "textured-4000-d3": (4000, 3, True)}
    EXACT = ("key", "bary", "energy", "recorded", "alive")

    def make_inputs(self, rng, case):
        m, depth, textured = case
        tables = _tables(rng)
        hits = _textured_smooth_hits(rng, tables, m) if textured else _hits(rng, tables, m)
        return tables, hits, depth, (123, 456)

    def device(self, tables, hits, depth, key):
        return ScatterCL(tables)(hits, depth, key)

    def twin(self, tables, hits, depth, key):
        return scatter_reference(tables, hits, depth, key)

    def rule(self, name, want):
        return (0.0, 0.0) if name in self.EXACT else (1e-6, 1e-6)


@pytest.mark.parametrize("depth", [0, 1, 7])
def test_record_keys_carry_the_direct_and_parity_bits(rng, depth):
    tables = _tables(rng)
    hits = _hits(rng, tables, 5000)
    out = scatter_reference(tables, hits, depth, (123, 456))
    assert out.recorded.any()
    assert (((out.key[out.recorded] & DIRECT_BIT) != 0) == (depth == 0)).all()
    odd = (hits.photon % 2 == 1)
    assert ((out.key[odd & out.recorded] & PARITY_BIT) != 0).all()
    assert not (out.key[~odd & out.recorded] & PARITY_BIT).any()


def test_bounce_properties(rng):
    tables = _tables(rng, kinds=(0, 1, 2))
    hits = _hits(rng, tables, 20_000)
    out = scatter_reference(tables, hits, 2, (5, 6))
    kind = tables.kind[tables.tri_mat[hits.tri]]
    n = tables.normals[hits.tri]
    facing = np.where((np.einsum("ij,ij->i", n, hits.dirs) < 0)[:, None], n, -n)
    # unit directions leaving on the facing side (diffuse and mirror); black surfaces absorb
    np.testing.assert_allclose(np.linalg.norm(out.dirs, axis=1), 1.0, atol=1e-5)
    leaving = np.einsum("ij,ij->i", out.dirs, facing)
    assert (leaving[(kind != 2)] > -1e-6).all()
    assert not out.alive[tables.tri_mat[hits.tri] == 0].any()
    # the mirror keeps the angle to the normal
    mirror = kind == 1
    np.testing.assert_allclose(leaving[mirror], -np.einsum("ij,ij->i", hits.dirs, facing)[mirror], atol=1e-5)
    # element ids stay inside their source triangle's range
    local = out.key[out.recorded] & np.uint32((1 << 30) - 1)
    t = hits.tri[out.recorded]
    assert (local >= tables.tri_offset[t]).all()
    assert (local < tables.tri_offset[t] + tables.tri_n[t].astype(np.int64) ** 2).all()


def test_record_constants_match_the_store():
    from pipeline.store import DIRECT_BIT as STORE_DIRECT
    from pipeline.store import PARITY_BIT as STORE_PARITY

    assert DIRECT_BIT == STORE_DIRECT and PARITY_BIT == STORE_PARITY


def _textured_smooth_hits(rng, tables, m) -> Hits:
    """Hits with their own albedo (a texture), shading normals tilted up to ~30 degrees off the
    geometric ones (vertex normals) and kinds and Phong exponents (a metallic-roughness texture),
    all given per hit as the tracer does."""
    hits = _hits(rng, tables, m)
    geo = tables.normals[hits.tri]
    tilt = geo + 0.6 * rng.normal(size=(m, 3)) * rng.random((m, 1))
    tilt /= np.linalg.norm(tilt, axis=1, keepdims=True)
    tilt *= np.where(np.einsum("ij,ij->i", tilt, geo) < 0, -1.0, 1.0)[:, None]
    hits.albedo = rng.random((m, 3))
    hits.albedo[: m // 10] = 0.0  # black texels absorb
    hits.shading = tilt
    hits.kind = rng.integers(0, 4, m).astype(np.int32)
    hits.exponent = rng.choice([0.5, 3.0, 40.0, 1e4], m)
    return hits


def test_bounce_follows_the_hit_albedo_and_shading_normal(rng):
    """Roulette uses the per-hit albedo (not the material's); diffuse directions are a cosine
    lobe about the shading normal; survivors leave on the geometric side they arrived from."""
    tables = _tables(rng, kinds=(0,))
    tables.albedo[:] = 1.0  # the material alone would never absorb
    hits = _textured_smooth_hits(rng, tables, 40_000)
    hits.kind = hits.exponent = None  # the material's kind: diffuse
    out = scatter_reference(tables, hits, 1, (1, 2))
    black = hits.albedo.max(axis=1) == 0
    assert not out.alive[black].any() and out.alive[~black].any()
    geo = tables.normals[hits.tri]
    fs = np.where(np.einsum("ij,ij->i", geo, hits.dirs) < 0, 1.0, -1.0)
    assert (np.einsum("ij,ij->i", out.dirs[out.alive], geo[out.alive]) * fs[out.alive] > 0).all()
    # weight of a survivor: beta x albedo / max(albedo)
    a = out.alive
    expected = hits.beta[a] * hits.albedo[a] / hits.albedo[a].max(axis=1, keepdims=True)
    np.testing.assert_allclose(out.beta[a], expected, rtol=1e-12)
    # mean cosine to the shading normal of a cosine lobe is 2/3 (before the geometric cut)
    cos_s = np.einsum("ij,ij->i", out.dirs, hits.shading * fs[:, None])
    flat = np.einsum("ij,ij->i", hits.shading, geo) > 0.999
    assert abs(cos_s[flat & (hits.albedo.max(axis=1) > 0)].mean() - 2 / 3) < 0.02


def test_bounce_follows_the_hit_kind(rng):
    """A per-hit kind overrides the material's: on an all-diffuse table, hits marked mirror record
    nothing and leave along the mirror direction about their shading normal, glossy ones gain the
    lobe's weight, diffuse ones record."""
    tables = _tables(rng, kinds=(0,))
    tables.albedo[:] = 1.0
    hits = _textured_smooth_hits(rng, tables, 20_000)
    hits.albedo = None
    out = scatter_reference(tables, hits, 1, (3, 4))
    hit = hits.tri >= 0
    assert (out.recorded == (hit & (hits.kind == 0))).all()
    geo = tables.normals[hits.tri]
    fs = np.where(np.einsum("ij,ij->i", geo, hits.dirs) < 0, 1.0, -1.0)
    n = hits.shading * fs[:, None]
    d = hits.dirs.astype(np.float64)
    mirror = d - 2 * np.einsum("ij,ij->i", d, n)[:, None] * n
    sel = (hits.kind == 1) & out.alive
    assert sel.sum() > 1000
    np.testing.assert_allclose(out.dirs[sel], mirror[sel], atol=1e-6)
    glossy = (hits.kind == 2) & out.alive
    cos_o = np.einsum("ij,ij->i", out.dirs[glossy].astype(np.float64), n[glossy])
    e = hits.exponent[glossy]
    np.testing.assert_allclose(out.beta[glossy], hits.beta[glossy] * (cos_o * (e + 2) / (e + 1))[:, None], rtol=1e-5)


def _fresnel(cos_i: float, eta: float) -> float:
    """Unpolarised Fresnel reflectance (Hecht, Optics, §4.6) for n1 / n2 = eta."""
    sin2_t = eta**2 * (1 - cos_i**2)
    if sin2_t >= 1:
        return 1.0
    cos_t = np.sqrt(1 - sin2_t)
    rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    rp = (eta * cos_t - cos_i) / (eta * cos_t + cos_i)
    return 0.5 * (rs**2 + rp**2)


@pytest.mark.parametrize("theta_deg, inside", [(0.0, False), (60.0, False), (30.0, True), (45.0, True)])
def test_glass_reflects_fresnels_share_and_refracts_by_snells_law(theta_deg, inside):
    """A glass (ior 1.5) triangle in the plane y = 0, normal +y, met from above (outside) or below
    (inside, leaving): the share reflected is Fresnel's (all of it past the critical angle, 41.8
    degrees, from inside), the rest leaves on the far side with sin(theta_t) = eta sin(theta_i)."""
    n = 40_000
    ccw = np.array([[-1e3, 0, -1e3, 0, 0, 1e3, 1e3, 0, -1e3]], np.float32)  # counter-clockwise seen from +y
    tables = SceneTables(corners=ccw,
                         normals=np.array([[0.0, 1.0, 0.0]]), tri_mat=np.zeros(1, np.int32),
                         tri_n=np.ones(1, np.int32), tri_offset=np.zeros(1, np.int64), albedo=np.ones((1, 3)),
                         kind=np.array([3], np.int32), exponent=np.zeros(1), epsilon=1e-4, ior=np.array([1.5]))
    theta = np.radians(theta_deg)
    d = np.array([np.sin(theta), np.cos(theta) if inside else -np.cos(theta), 0.0])
    hits = Hits(np.zeros(n, np.int32), np.full(n, 0.3, np.float32), np.full(n, 0.3, np.float32),
                np.tile(d, (n, 1)).astype(np.float32), np.ones((n, 3)), np.arange(n, dtype=np.int64))
    out = scatter_reference(tables, hits, 1, (5, 6))
    eta = 1.5 if inside else 1 / 1.5
    f = _fresnel(np.cos(theta), eta)
    up = out.dirs[:, 1] > 0
    reflected = up if not inside else ~up
    assert out.alive.all() and not out.recorded.any()
    assert abs(reflected.mean() - f) < 4 * np.sqrt(max(f * (1 - f), 1e-12) / n) + 1e-9
    if f < 1:
        t = out.dirs[~reflected].astype(np.float64)
        np.testing.assert_allclose(np.hypot(t[:, 0], t[:, 2]), eta * np.sin(theta), atol=1e-6)  # Snell
        np.testing.assert_allclose(np.linalg.norm(t, axis=1), 1.0, atol=1e-6)
        device = ScatterCL(tables)(hits, 1, (5, 6))
        np.testing.assert_array_equal(device.alive, out.alive)
        np.testing.assert_allclose(device.dirs, out.dirs, atol=1e-6)
