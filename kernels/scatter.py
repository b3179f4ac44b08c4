"""One photon bounce after the hits are known: record, Russian roulette, next direction.

``scatter_reference`` (NumPy, float64) and :class:`ScatterCL` (``scatter.cl`` on PoCL) compute the
same thing from the same Philox numbers (kernels/philox.py); the tracer in pipeline/photons/tracing.py uses
either. Per hit on triangle t with material m, photon index i, bounce d:

* diffuse: record (element, b1, b2, weight) with the element located as ElementMesh.locate does;
  key bit 30 = i odd, bit 31 = (d == 0); the next direction is cosine-weighted about the shading
  normal turned to the side the geometric normal faces the incoming ray (Malley's method; pbrt-v4
  §A.5.3).
* mirror: next direction is the reflection of the incoming one about that shading normal.
* glossy: a normalised Phong lobe about the mirror direction, pdf (e+1)/(2 pi) cos^e, sampled as
  cos = u^(1/(e+1)); the weight gains rho (e+2)/(e+1) cos_o (BRDF x cos / pdf, Lafortune and
  Willems 1994); directions below the surface end the path.
* dielectric (solid glass): with probability F (Fresnel's equations for unpolarised light, the
  mean of the s and p reflectances; 1 past the critical angle) the mirror direction, else the
  refracted one, ``eta d + (eta cos_i - cos_t) n`` with ``eta = 1 / ior`` entering (where the
  geometric normal faces the ray) and ``ior`` leaving (pbrt-v4 §9.3, §9.5); the choice is the
  direction's first word (unused by a smooth surface's sampling). A refracted photon leaves on the
  other side.
* Russian roulette: survive with q = max(albedo), weight x albedo / q (Arvo and Kirk 1990); the
  albedo is the hit's own base colour (textures, vertex colours: pipeline/scene/shading.py).
* the kind and the exponent are the hit's own too where a metallic-roughness texture varies them
  (``Hits.kind``), else its material's.
* a new direction that leaves below the geometric surface (possible with shading normals) ends the
  path, so no photon leaks through a surface; the origin offset follows the geometric normal.

Words of Philox counter (i_lo, i_hi, d, 0) under key (seed, frame): x -> roulette, y, z -> direction.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .cells import locate_in_triangles
from .context import LANES, WORK_GROUP, device_input, device_output, device_table, read_back
from .philox import uniforms
from .record_layout import BARY_SCALE, DIRECT_BIT, PARITY_BIT
from .sampling import around

KIND_CODE = {"diffuse": 0, "mirror": 1, "glossy": 2, "dielectric": 3}


@dataclass
class SceneTables:
    """Per-frame-state tables the bounce needs (uploaded once per state to the device)."""

    corners: np.ndarray  # (F, 9) float32 world corners
    normals: np.ndarray  # (F, 3) float64 unit counter-clockwise normals
    tri_mat: np.ndarray  # (F,) int32
    tri_n: np.ndarray  # (F,) int32 element split factor
    tri_offset: np.ndarray  # (F,) int64 first element
    albedo: np.ndarray  # (M, 3) float64
    kind: np.ndarray  # (M,) int32
    exponent: np.ndarray  # (M,) float64
    epsilon: float  # relative self-intersection offset (surface_offset)
    ior: np.ndarray | None = None  # (M,) float64 index of refraction of dielectrics; None: the scene has none


@dataclass
class Hits:
    """The bounce's input: hits of live photons."""

    tri: np.ndarray  # int32, -1 for a miss
    u: np.ndarray  # float32 (Embree barycentrics)
    v: np.ndarray  # float32
    dirs: np.ndarray  # (m, 3) float32 incoming directions
    beta: np.ndarray  # (m, 3) float64 weights
    photon: np.ndarray  # int64 photon indices
    albedo: np.ndarray | None = None  # (m, 3) float64 base colour at the hit; None: the material's
    shading: np.ndarray | None = None  # (m, 3) float64 unit shading normal; None: the geometric one
    kind: np.ndarray | None = None  # (m,) kind code at the hit (metallic-roughness textures); None: the material's
    exponent: np.ndarray | None = None  # (m,) float64 Phong exponent at the hit, with ``kind``


def hit_albedo(tables: SceneTables, hits: Hits) -> np.ndarray:
    """(m, 3) float64 albedo of every hit: ``hits.albedo`` or its material's."""
    if hits.albedo is not None:
        return np.asarray(hits.albedo, np.float64)
    return np.take(tables.albedo, np.take(tables.tri_mat, np.maximum(hits.tri, 0)), axis=0)


def hit_kind(tables: SceneTables, hits: Hits) -> tuple[np.ndarray, np.ndarray]:
    """(int32 kind code, float64 Phong exponent) of every hit: ``hits.kind``/``exponent`` or its material's."""
    if hits.kind is not None:
        return np.asarray(hits.kind, np.int32), np.asarray(hits.exponent, np.float64)
    m = np.take(tables.tri_mat, np.maximum(hits.tri, 0))
    return np.take(tables.kind, m), np.take(tables.exponent, m)


def hit_ior(tables: SceneTables, hits: Hits) -> np.ndarray:
    """(m,) float64 index of refraction of every hit's material (1 where the scene has no dielectric)."""
    if tables.ior is None:
        return np.ones(len(hits.tri))
    return np.take(tables.ior, np.take(tables.tri_mat, np.maximum(hits.tri, 0)))


def hit_shading(tables: SceneTables, hits: Hits) -> np.ndarray:
    """(m, 3) float64 shading normal of every hit: ``hits.shading`` or the geometric normal."""
    if hits.shading is not None:
        return np.asarray(hits.shading, np.float64)
    return np.take(tables.normals, np.maximum(hits.tri, 0), axis=0)


@dataclass
class Bounce:
    """The bounce's output, one row per input hit (``recorded`` and ``alive`` select)."""

    key: np.ndarray  # uint32
    bary: np.ndarray  # (m, 2) uint16
    energy: np.ndarray  # (m, 3) float32
    recorded: np.ndarray  # bool
    origins: np.ndarray  # (m, 3) float32
    dirs: np.ndarray  # (m, 3) float32
    beta: np.ndarray  # (m, 3) float64
    alive: np.ndarray  # bool


def surface_offset(corners: np.ndarray, epsilon: float) -> np.ndarray:
    """Self-intersection offset of triangles with float32 ``corners`` (n, 9): ``epsilon`` times the
    largest corner magnitude, at least FLT_MIN (pipeline/photons/raycast.py says why); lanes.cl's
    ``surface_offset8``, to the bit."""
    scale = np.abs(np.asarray(corners, np.float32).astype(np.float64).reshape(len(corners), 9)).max(
        axis=1, initial=0.0)
    return epsilon * np.maximum(scale, float(np.finfo(np.float32).tiny))


def glossy_cos(tables: SceneTables, hits: Hits, depth: int, key: tuple[int, int]) -> np.ndarray:
    """cos of the Phong lobe's angle, u1^(1/(e+1)), for the glossy hits (0 elsewhere). Both backends
    take it from here: pow is a libm call, which would differ between NumPy and PoCL."""
    out = np.zeros(max(len(hits.tri), 1))
    if hits.kind is None and not (tables.kind == 2).any():
        return out
    kind, exponent = hit_kind(tables, hits)
    glossy = np.flatnonzero((hits.tri >= 0) & (kind == 2))
    if len(glossy):
        u1 = uniforms(hits.photon[glossy], depth, key)[:, 1]
        out[glossy] = u1 ** (1.0 / (exponent[glossy] + 1.0))
    return out


def scatter_reference(tables: SceneTables, hits: Hits, depth: int, key: tuple[int, int]) -> Bounce:
    """NumPy twin of ``scatter.cl`` (see the module docstring). A miss (triangle -1) records
    nothing and ends its path."""
    m_count = len(hits.tri)
    hit = hits.tri >= 0
    t = np.where(hit, hits.tri, 0).astype(np.int64)
    kind, exponent = hit_kind(tables, hits)
    u, v = hits.u.astype(np.float64), hits.v.astype(np.float64)
    c = tables.corners[t].astype(np.float64).reshape(-1, 3, 3)
    p = (1 - u - v)[:, None] * c[:, 0] + u[:, None] * c[:, 1] + v[:, None] * c[:, 2]
    n = tables.normals[t]
    d = hits.dirs.astype(np.float64)
    fs = np.where(np.einsum("ij,ij->i", n, d) < 0, 1.0, -1.0)  # the side the photon arrives from
    facing = hit_shading(tables, hits) * fs[:, None]
    beta = hits.beta.copy()

    # Record diffuse hits (the element mesh's own locate)
    recorded = hit & (kind == 0)
    element, b1, b2 = locate_in_triangles(tables.tri_n, tables.tri_offset, t, u, v)
    key_out = element.astype(np.uint32)
    key_out |= np.where(hits.photon % 2 == 1, PARITY_BIT, np.uint32(0))
    if depth == 0:
        key_out |= DIRECT_BIT
    bary = np.stack([np.rint(b1 * float(BARY_SCALE)), np.rint(b2 * float(BARY_SCALE))], 1).astype(np.uint16)
    energy = beta.astype(np.float32)
    key_out[~recorded] = 0
    bary[~recorded] = 0
    energy[~recorded] = 0

    # Russian roulette and the next direction
    w = uniforms(hits.photon, depth, key)
    rho = hit_albedo(tables, hits)
    q = rho.max(axis=1)
    survive = w[:, 0] < q
    beta = beta * rho / np.where(q > 0, q, 1.0)[:, None]
    dn = np.einsum("ij,ij->i", d, facing)
    mirror = d - 2.0 * dn[:, None] * facing
    nd = np.empty((m_count, 3))
    diffuse = kind == 0
    nd[diffuse] = around(facing[diffuse], np.sqrt(1.0 - w[diffuse, 1]), 2.0 * np.pi * w[diffuse, 2],
                         polynomial=True)
    nd[kind == 1] = mirror[kind == 1]
    refracts = np.zeros(m_count, bool)
    dielectric = np.flatnonzero(kind == 3)
    if len(dielectric):
        refracts[dielectric], nd[dielectric] = refract_or_reflect(d[dielectric], facing[dielectric], fs[dielectric],
                                                                  hit_ior(tables, hits)[dielectric], w[dielectric, 1])
    glossy = kind == 2
    if glossy.any():
        e = exponent[glossy]
        cos_a = glossy_cos(tables, hits, depth, key)[glossy]
        g = around(mirror[glossy], cos_a, 2.0 * np.pi * w[glossy, 2], polynomial=True)
        cos_o = np.einsum("ij,ij->i", g, facing[glossy])
        beta[glossy] *= (np.maximum(cos_o, 0.0) * (e + 2.0) / (e + 1.0))[:, None]
        survive[glossy] &= cos_o > 0
        nd[glossy] = g
    n_out = np.einsum("ij,ij->i", n, nd)
    survive &= np.where(refracts, n_out * fs < 0, n_out * fs > 0)  # the other side only where it refracts
    side = np.where(n_out < 0, -1.0, 1.0)
    origins = (p + n * (side * surface_offset(tables.corners[t], tables.epsilon))[:, None]).astype(np.float32)
    return Bounce(key_out, bary, energy, recorded, origins, nd.astype(np.float32), beta, survive & hit)


def refract_or_reflect(d: np.ndarray, facing: np.ndarray, fs: np.ndarray, ior: np.ndarray,
                       u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(refracts, next direction) of rays ``d`` (n, 3) meeting solid glass, as scatter.cl computes
    them (the module docstring): ``facing`` the unit shading normals on the incoming side, ``fs``
    > 0 where the ray meets the front (entering), ``u`` uniform numbers against Fresnel's share.
    The compositor's paths refract with it too (pipeline/frames/camera_paths.py)."""
    dn = np.einsum("ij,ij->i", d, facing)
    mirror = d - 2.0 * dn[:, None] * facing
    eta = np.where(fs > 0, 1.0 / ior, ior)
    cos_i = np.minimum(-dn, 1.0)
    sin2_t = eta * eta * (1.0 - cos_i * cos_i)
    tir = sin2_t >= 1.0
    cos_t = np.sqrt(np.maximum(1.0 - sin2_t, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):  # 0/0 only at grazing total reflection, unused
        rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
        rp = (eta * cos_t - cos_i) / (eta * cos_t + cos_i)
    fresnel = np.where(tir, 1.0, 0.5 * (rs * rs + rp * rp))
    refracts = u >= fresnel
    refracted = eta[:, None] * d + (eta * cos_i - cos_t)[:, None] * facing
    return refracts, np.where(refracts[:, None], refracted, mirror)


class ScatterCL:
    """``scatter.cl`` with the scene tables resident on the device; one instance per frame state."""

    def __init__(self, tables: SceneTables):
        import pyopencl as cl  # only when a kernel runs: twins need no OpenCL

        from .context import device_context, kernel  # imports pyopencl: only when a kernel runs

        self._cl = cl
        self.ctx, self.queue = device_context()
        self.kernel = kernel("scatter", "scatter8")
        self.tables = tables
        self._pool = None  # output arrays reused from call to call (_output_rows)
        self._ones = None  # the index of refraction of every hit of a scene without glass (_hit_ior)
        self._tables = [device_table(self.ctx, a, dt) for a, dt in (
            (tables.corners, np.float32), (tables.normals, np.float64),
            (tables.tri_n, np.int32), (tables.tri_offset, np.int64))]

    def __call__(self, hits: Hits, depth: int, key: tuple[int, int]) -> Bounce:
        """One bounce on the device. The returned arrays are this instance's and are overwritten by
        its next call."""
        cl = self._cl
        m = len(hits.tri)
        if m == 0:
            return scatter_reference(self.tables, hits, depth, key)
        # A fixed work-group size: PoCL specialises (and compiles) a kernel per local size, so a
        # size chosen per launch would recompile for every new wavefront length.
        items = -(-m // LANES)  # eight rays a work item
        padded = -(-items // WORK_GROUP) * WORK_GROUP
        inputs = [device_input(self.ctx, a) for a in (
            hits.tri.astype(np.int32, copy=False), hits.u.astype(np.float32, copy=False),
            hits.v.astype(np.float32, copy=False), hits.dirs.astype(np.float32, copy=False),
            hits.beta.astype(np.float64, copy=False), hits.photon.astype(np.int64, copy=False),
            glossy_cos(self.tables, hits, depth, key), hit_albedo(self.tables, hits),
            hit_shading(self.tables, hits), *hit_kind(self.tables, hits), self._hit_ior(hits))]
        out = Bounce(*self._output_rows(m))
        fields = ("key", "bary", "energy", "recorded", "origins", "dirs", "beta", "alive")
        outputs = [device_output(self.ctx, getattr(out, f)) for f in fields]
        self.kernel.set_args(np.int64(m), np.int32(depth), np.uint32(key[0] & 0xFFFFFFFF),
                             np.uint32(key[1] & 0xFFFFFFFF), np.float64(self.tables.epsilon),
                             *inputs, *self._tables, *outputs)
        cl.enqueue_nd_range_kernel(self.queue, self.kernel, (padded,), (WORK_GROUP,))
        read_back(self.queue, [getattr(out, f) for f in fields], outputs)
        out.recorded = out.recorded.view(bool)
        out.alive = out.alive.view(bool)
        return out

    def _hit_ior(self, hits: Hits) -> np.ndarray:
        """:func:`hit_ior`, without a new array of ones every bounce where the scene has no glass."""
        if self.tables.ior is not None:
            return hit_ior(self.tables, hits)
        if self._ones is None or len(self._ones) < len(hits.tri):
            self._ones = np.ones(max(len(hits.tri), 1))
        return self._ones[:len(hits.tri)]

    _OUTPUTS = ((np.uint32, ()), (np.uint16, (2,)), (np.float32, (3,)), (np.uint8, ()), (np.float32, (3,)),
                (np.float32, (3,)), (np.float64, (3,)), (np.uint8, ()))

    def _output_rows(self, m: int) -> list[np.ndarray]:
        """The first ``m`` rows of this instance's output arrays, grown when needed. Reusing them
        spares the kernel the page faults of fresh memory on every bounce; the result of a call is
        therefore valid only until the next call (the tracer copies what it keeps out of it)."""
        if self._pool is None or len(self._pool[0]) < m:
            self._pool = [np.empty((max(m, 1),) + shape, dtype) for dtype, shape in self._OUTPUTS]
        return [a[:m] for a in self._pool]
