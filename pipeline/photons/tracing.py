"""Photon shooting (§4): trace one frame's batch of photons from the lights and record diffuse hits.

The tracer is wavefront-style: all live photons of a chunk advance one bounce per Embree call, in
large float32 batches, and one OpenCL kernel (kernels/scatter.cl) records the diffuse hits and
samples the next directions for the whole wavefront. A photon that reaches the back face of a
single-sided material (glTF ``doubleSided`` false, pipeline/scene/materials.py) is absorbed there:
the hit counts as a miss, so nothing is recorded and the path ends. At a diffuse hit the photon is recorded
(element, barycentrics inside the element, RGB weight, direct = first hit) and bounces
Lambertian about the shading normal; mirrors reflect, glossy surfaces sample a normalised Phong
lobe. Russian roulette on the hit's base colour (factor x texture x vertex colour,
pipeline/scene/shading.py) ends paths, unbiased; ``max_depth`` hits (PhotonConfig.photon_depth,
256) is only a safety net for rooms of albedo 1, and the photons it cuts are counted
(``stats["capped"]``): a cap of 8 cut rho^8 of the light in a closed room (17 % at albedo 0.8,
tests/stress/test_furnace.py).
``backend="numpy"`` runs the kernel's NumPy twin instead (kernels/scatter.py).

Determinism: every random number of photon i of frame f is a Philox word of the counter
(i, stream) under the key (seed, f) (kernels/philox.py), so a photon's path depends on nothing
but those numbers: not on batch boundaries, chunking, worker or worker count. Photon i has parity
i % 2 (even/odd halves for the AQM, §5.2.3).

Record layout: pipeline/store/records.py (20 bytes: key with element id, parity bit 30, direct
bit 31; two uint16 barycentrics; three float32 weights).
"""
from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from kernels.emit import AREA, EmissionTables, EmitCL, emit_reference
from kernels.record_layout import DIRECT_BIT, ELEMENT_MASK
from kernels.scatter import KIND_CODE, Hits, ScatterCL, SceneTables, scatter_reference
from pipeline.config import PhotonConfig
from pipeline.scene import ElementMesh, FrameState
from pipeline.scene.environment import EnvironmentMap
from pipeline.scene.shading import SurfaceShading

from .emission import emission_tables, environment_photons, textured_emission_weights
from .raycast import RayCaster, caster_for
from .sidedness import absorb_back_hits, one_sided_triangles

CHUNK = 1 << 17  # photons per wavefront: bounds memory per worker (about 0.5 GB at most)
BACKENDS = ("opencl", "numpy")


@dataclass
class PhotonBatch:
    """The records of one (frame, batch), unsorted, plus counters."""

    key: np.ndarray  # (n,) uint32
    bary: np.ndarray  # (n, 2) uint16
    energy: np.ndarray  # (n, 3) float32 photon weight (flux x N emitted, see pipeline/photons/emission.py)
    photons_emitted: int
    photon_start: int
    rays_cast: int = 0
    stats: dict = field(default_factory=dict)

    def indirect(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(element, b1, b2, energy) of the records that are not a light's first hit, decoded as
        kernels/record_layout.py lays the key out: what a map made straight from a batch, with no
        store, sums (the pilot of pipeline/segments/planner.py, the benchmark's reference)."""
        keep = (self.key & DIRECT_BIT) == 0
        return self.key[keep] & np.uint32(ELEMENT_MASK), self.bary[keep, 0], self.bary[keep, 1], self.energy[keep]


def scene_tables(state: FrameState, elements: ElementMesh, caster: RayCaster) -> SceneTables:
    """The per-triangle and per-material tables the bounce kernel reads."""
    mats = state.materials
    return SceneTables(
        corners=state.vertices[state.faces].reshape(-1, 9).astype(np.float32),
        normals=caster.normals, tri_mat=state.triangle_material.astype(np.int32),
        tri_n=elements.triangle_n.astype(np.int32), tri_offset=elements.triangle_offset[:-1].astype(np.int64),
        albedo=np.array([m.albedo for m in mats], np.float64),
        kind=np.array([KIND_CODE[m.kind] for m in mats], np.int32),
        exponent=np.array([m.phong_exponent for m in mats], np.float64), epsilon=caster.epsilon,
        ior=(np.array([m.ior for m in mats], np.float64) if any(m.kind == "dielectric" for m in mats) else None))


_scatterers: OrderedDict[tuple, object] = OrderedDict()


def _kernels(state: FrameState, elements: ElementMesh, caster: RayCaster, backend: str):
    """(emit, scatter, emission tables) for a frame state, built (and uploaded) once per process."""
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    cache_key = (state.state_key, elements.element_size, elements.n_elements, backend)
    found = _scatterers.get(cache_key)
    if found is None:
        tables = scene_tables(state, elements, caster)
        emission = emission_tables(state, caster)
        if emission is None:
            found = (None, None, None)
        elif backend == "opencl":
            found = (EmitCL(emission), ScatterCL(tables), emission)
        else:
            found = (lambda photon, key: emit_reference(emission, photon, key),
                     lambda hits, depth, key: scatter_reference(tables, hits, depth, key), emission)
        _scatterers[cache_key] = found
        while len(_scatterers) > 4:
            _scatterers.popitem(last=False)
    return found


@dataclass(frozen=True)
class PhotonRange:
    """Photons ``start .. start + count - 1`` of Philox stream ``frame``: with the run's seed, the
    key of their random numbers (kernels/philox.py)."""

    frame: int
    start: int
    count: int


def trace_batch(state: FrameState, elements: ElementMesh, photons: PhotonRange, config: PhotonConfig, *,
                caster: RayCaster | None = None, backend: str = "opencl") -> PhotonBatch:
    """Trace ``photons`` with ``config``'s seed and depth cap in the scene as posed in ``state``;
    return their diffuse-hit records (unsorted; the store sorts)."""
    if photons.count <= 0:
        raise ValueError(f"n_photons must be positive, got {photons.count}")
    caster = caster or caster_for(state)
    emit, scatter, table = _kernels(state, elements, caster, backend)
    if table is None:  # nothing emits at this instant: the photons are emitted and carry nothing
        return PhotonBatch(np.empty(0, np.uint32), np.empty((0, 2), np.uint16), np.empty((0, 3), np.float32),
                           photons.count, photons.start, 0, {"records": 0, "direct": 0, "capped": 0})
    tracer = _Tracer(state, caster, table, emit, scatter, SurfaceShading(state, caster.normals),
                     one_sided_triangles(state), (int(config.seed) & 0xFFFFFFFF, int(photons.frame) & 0xFFFFFFFF),
                     config.photon_depth)
    rays_before = caster.rays_cast
    parts, capped = [], [0]
    for lo in range(0, photons.count, CHUNK):
        photon = photons.start + lo + np.arange(min(CHUNK, photons.count - lo), dtype=np.int64)
        parts.extend(_trace_wavefront(tracer, photon, capped))
    if parts:
        key_out = np.concatenate([p[0] for p in parts])
        bary = np.concatenate([p[1] for p in parts])
        energy = np.concatenate([p[2] for p in parts])
    else:
        key_out, bary, energy = np.empty(0, np.uint32), np.empty((0, 2), np.uint16), np.empty((0, 3), np.float32)
    direct = int(np.count_nonzero(key_out & DIRECT_BIT))
    return PhotonBatch(key_out, bary, energy, photons.count, photons.start, caster.rays_cast - rays_before,
                       {"records": len(key_out), "direct": direct, "capped": capped[0]})


@dataclass(frozen=True)
class _Tracer:
    """What every wavefront of one batch reads: the posed scene, its rays, the kernels and their
    tables, the surfaces' shading, the single-sided triangles, the Philox key and the depth cap."""

    state: FrameState
    caster: RayCaster
    table: EmissionTables
    emit: Callable
    scatter: Callable
    surface: SurfaceShading
    one_sided: np.ndarray | None
    key: tuple[int, int]
    max_depth: int


def _trace_wavefront(tracer: _Tracer, photon: np.ndarray, capped: list[int]):
    """Yield (key, bary, energy) record arrays of one wavefront of photons, bounce by bounce; add
    the photons still alive after ``tracer.max_depth`` hits to ``capped[0]``. The base colour and
    shading normal at each hit come from ``tracer.surface`` (pipeline/scene/shading.py)."""
    state, caster, table, surface, key = tracer.state, tracer.caster, tracer.table, tracer.surface, tracer.key
    origins, dirs, beta, emitter = tracer.emit(photon, key)
    if isinstance(state.sky, EnvironmentMap):  # an HDRI: its photons by its own importance
        origins, dirs, beta = environment_photons(table, state.sky, photon, emitter, key, (origins, dirs, beta))
    if surface.emission_varies:  # emissive textures: weight by the texture at each origin
        beta = beta * textured_emission_weights(table, surface, caster, photon, emitter, key)
    for depth in range(tracer.max_depth):
        if not len(photon):
            return
        tri, u, v, dist = caster.intersect(origins, dirs)
        tri = absorb_back_hits(tri, dirs, caster.normals, tracer.one_sided)
        if depth == 0 and any(li.definition.range is not None for li in state.lights):
            beta = beta * _range_window(state, table, emitter, dist)[:, None]
        kept = surface.volume_transmittance(tri, dirs, dist)  # light absorbed inside coloured glass
        if kept is not None:
            beta = beta * kept
        kind, exponent = surface.kinds(tri, u, v) if surface.kind_varies else (None, None)
        hits = Hits(tri, u, v, dirs, beta, photon, albedo=surface.base_color(tri, u, v) if surface.varies else None,
                    shading=surface.normal(tri, u, v) if surface.smooth else None, kind=kind, exponent=exponent)
        bounce = tracer.scatter(hits, depth, key)  # misses end there
        # Keep the recorded hits and the survivors, in order (np.take: several times faster than
        # fancy indexing for rows of 2-D arrays)
        rec = np.flatnonzero(bounce.recorded)
        if len(rec):
            yield (np.take(bounce.key, rec), np.take(bounce.bary, rec, axis=0),
                   np.take(bounce.energy, rec, axis=0))
        live = np.flatnonzero(bounce.alive)
        origins, dirs = np.take(bounce.origins, live, axis=0), np.take(bounce.dirs, live, axis=0)
        beta, photon = np.take(bounce.beta, live, axis=0), np.take(photon, live)
    capped[0] += len(photon)


def _range_window(state: FrameState, table, emitter: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Punctual lights' range cut-off applied at the first hit (1 where a light has no range)."""
    w = np.ones(len(dist))
    for j, light in enumerate(state.lights):
        if light.definition.range is None:
            continue
        sel = (table.kind[emitter] != AREA) & (table.index[emitter] == j)
        w[sel] = light.range_window(dist[sel])
    return w
