"""Photon shooting (§4): trace one frame's batch of photons from the lights and record diffuse hits.

The tracer is wavefront-style: all live photons of a chunk advance one bounce per Embree call, in
large float32 batches. At a diffuse hit the photon is recorded (element, barycentrics inside the
element, RGB weight, direct = first hit) and bounces Lambertian (cosine sampling); mirrors reflect,
glossy surfaces sample a normalised Phong lobe. Russian roulette on the albedo ends paths; a
photon also ends after ``max_depth`` hits.

Determinism: photons are traced in chunks of :data:`CHUNK` with a generator seeded by
(seed, frame, batch, chunk), so a batch's records depend only on those numbers, never on which
worker runs it or how many there are. Photon ``photon_start + i`` of a batch has parity
``(photon_start + i) % 2`` (even/odd halves for the AQM, §5.2.3).

Record key layout (20-byte records, pipeline/store.py): bits 0-29 element id, bit 30 parity
(1 = odd photon), bit 31 direct flag.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.scene import ElementMesh, FrameState

from .emission import cosine_hemisphere, emit, emitter_table, around
from .raycast import RayCaster, caster_for

CHUNK = 1 << 17  # photons per RNG stream and per wavefront; bounds memory per worker
PARITY_BIT = np.uint32(1 << 30)
DIRECT_BIT = np.uint32(1 << 31)
ELEMENT_MASK = np.uint32((1 << 30) - 1)
BARY_SCALE = 65535.0

_KIND_CODE = {"diffuse": 0, "mirror": 1, "glossy": 2}


@dataclass
class PhotonBatch:
    """The records of one (frame, batch), unsorted, plus counters."""

    key: np.ndarray  # (n,) uint32
    bary: np.ndarray  # (n, 2) uint16
    energy: np.ndarray  # (n, 3) float32 photon weight (flux x N emitted, see workers/emission.py)
    photons_emitted: int
    photon_start: int
    rays_cast: int = 0
    stats: dict = field(default_factory=dict)


def chunk_rng(seed: int, frame: int, batch: int, chunk: int) -> np.random.Generator:
    """The counter-based stream of one chunk: Philox keyed by (seed, frame, batch, chunk)."""
    return np.random.Generator(np.random.Philox(np.random.SeedSequence([seed, frame, batch, chunk])))


def trace_batch(state: FrameState, elements: ElementMesh, *, n_photons: int, photon_start: int,
                seed: int, frame: int, batch: int, max_depth: int,
                caster: RayCaster | None = None) -> PhotonBatch:
    """Trace ``n_photons`` photons of (frame, batch) and return their diffuse-hit records."""
    if n_photons <= 0:
        raise ValueError(f"n_photons must be positive, got {n_photons}")
    caster = caster or caster_for(state)
    rays_before = caster.rays_cast
    table = emitter_table(state, caster)
    mats = state.materials
    albedo = np.array([m.albedo for m in mats], dtype=np.float64)
    kind = np.array([_KIND_CODE[m.kind] for m in mats], dtype=np.int8)
    exponent = np.array([m.phong_exponent for m in mats], dtype=np.float64)
    tri_mat = state.triangle_material
    verts = state.vertices.astype(np.float64)
    parts = []
    for c, lo in enumerate(range(0, n_photons, CHUNK)):
        n = min(CHUNK, n_photons - lo)
        rng = chunk_rng(seed, frame, batch, c)
        parts.append(_trace_chunk(state, elements, caster, table, rng, n, photon_start + lo, max_depth,
                                  albedo, kind, exponent, tri_mat, verts))
    key = np.concatenate([p[0] for p in parts])
    bary = np.concatenate([p[1] for p in parts])
    energy = np.concatenate([p[2] for p in parts])
    return PhotonBatch(key, bary, energy, n_photons, photon_start, caster.rays_cast - rays_before,
                       {"records": len(key), "direct": int((key & DIRECT_BIT).astype(bool).sum())})


def _trace_chunk(state, elements, caster, table, rng, n, first_index, max_depth,
                 albedo, kind, exponent, tri_mat, verts):
    origins, dirs, beta, emitter = emit(table, state, caster, n, rng)
    photon = first_index + np.arange(n, dtype=np.int64)
    keys, barys, energies = [], [], []
    for depth in range(max_depth):
        if not len(photon):
            break
        tri, u, v, dist = caster.intersect(origins, dirs)
        hit = tri >= 0
        if depth == 0:
            beta = beta * _range_window(state, table, emitter, dist)[:, None]
        tri, u, v, dirs, beta, photon = tri[hit], u[hit], v[hit], dirs[hit], beta[hit], photon[hit]
        if not len(photon):
            break
        corners = verts[state.faces[tri]]
        points = (1 - u - v)[:, None] * corners[:, 0] + u[:, None] * corners[:, 1] + v[:, None] * corners[:, 2]
        m = tri_mat[tri]
        k = kind[m]

        # Record every diffuse hit
        diffuse = k == 0
        if diffuse.any():
            elem, b1, b2 = elements.locate(tri[diffuse], u[diffuse], v[diffuse])
            key = elem.astype(np.uint32) | np.where(photon[diffuse] % 2 == 1, PARITY_BIT, np.uint32(0))
            if depth == 0:
                key |= DIRECT_BIT
            keys.append(key.astype(np.uint32))
            barys.append(np.stack([np.rint(b1 * BARY_SCALE), np.rint(b2 * BARY_SCALE)], 1).astype(np.uint16))
            energies.append(beta[diffuse].astype(np.float32))

        # Russian roulette on the albedo: survive with q = max channel, reweight by albedo / q
        rho = albedo[m]
        q = rho.max(axis=1)
        survive = rng.random(len(photon)) < q
        beta = beta * rho / np.where(q > 0, q, 1.0)[:, None]

        # Scatter: cosine lobe on diffuse, mirror reflection, Phong lobe about the mirror direction
        normal = caster.normals[tri]
        facing = np.where(np.einsum("ij,ij->i", normal, dirs) < 0, 1.0, -1.0)[:, None] * normal
        mirror_dir = dirs - 2.0 * np.einsum("ij,ij->i", dirs, facing)[:, None] * facing
        new_dirs = np.empty_like(dirs)
        if diffuse.any():
            new_dirs[diffuse] = cosine_hemisphere(facing[diffuse], rng)
        mirror = k == 1
        new_dirs[mirror] = mirror_dir[mirror]
        glossy = np.flatnonzero(k == 2)
        if len(glossy):
            e = exponent[m[glossy]]
            cos_a = rng.random(len(glossy)) ** (1.0 / (e + 1.0))  # pdf (e+1)/(2 pi) cos^e (pbrt-v3 §14.1)
            g = around(mirror_dir[glossy], cos_a, 2.0 * np.pi * rng.random(len(glossy)))
            cos_o = np.einsum("ij,ij->i", g, facing[glossy])
            # normalised Phong BRDF rho (e+2)/(2 pi) cos^e over that pdf, times cos_o
            beta[glossy] *= (np.maximum(cos_o, 0.0) * (e + 2.0) / (e + 1.0))[:, None]
            survive[glossy] &= cos_o > 0
            new_dirs[glossy] = g
        sel = survive
        origins = caster.offset_origins(points[sel], tri[sel], new_dirs[sel])
        dirs, beta, photon = new_dirs[sel], beta[sel], photon[sel]
        emitter = None

    if not keys:
        return np.empty(0, np.uint32), np.empty((0, 2), np.uint16), np.empty((0, 3), np.float32)
    return np.concatenate(keys), np.concatenate(barys), np.concatenate(energies)


def _range_window(state: FrameState, table, emitter: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Punctual lights' range cut-off applied at the first hit (1 where a light has no range)."""
    w = np.ones(len(dist))
    for j, light in enumerate(state.lights):
        if light.definition.range is None:
            continue
        sel = (table.kind[emitter] != 3) & (table.index[emitter] == j)
        w[sel] = light.range_window(dist[sel])
    return w


def shoot_task(*, store_url: str, scene_path: str, scene_hash: str, element_size: float,
               frame: int, frame_index: int, batch: int, n_photons: int, photon_start: int,
               seed: int, max_depth: int) -> dict:
    """Dask task: trace (frame, batch) and write it to the photon store; skip it if done.

    Plain arguments in, a small dict of counters out; runs the same with or without a cluster.
    """
    import time

    from pipeline.store import PhotonStore

    from .scene_cache import load_elements, load_scene

    store = PhotonStore.open(store_url, mode="r+")
    if store.is_done(frame_index, batch):
        return {"frame": frame, "batch": batch, "skipped": True}
    t0 = time.perf_counter()
    scene = load_scene(scene_path, scene_hash)
    elements = load_elements(scene_path, scene_hash, element_size)
    state = scene.pose_frame(frame)
    t1 = time.perf_counter()
    result = trace_batch(state, elements, n_photons=n_photons, photon_start=photon_start, seed=seed,
                         frame=frame, batch=batch, max_depth=max_depth)
    t2 = time.perf_counter()
    store.write_batch(frame_index, batch, key=result.key, bary=result.bary, energy=result.energy,
                      photons_emitted=n_photons, photon_start=photon_start)
    t3 = time.perf_counter()
    return {"frame": frame, "batch": batch, "skipped": False, "photons": n_photons,
            "records": len(result.key), "rays": result.rays_cast,
            "pose_s": t1 - t0, "trace_s": t2 - t1, "write_s": t3 - t2}
