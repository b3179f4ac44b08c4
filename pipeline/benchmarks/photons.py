"""``loom bench photons``: tracer throughput against raw Embree on the same frame, in one run.

For each scene, ``workers`` processes run at once (like Dask workers, one thread each). Each
traces ``photons`` photons of one frame, then casts as many incoherent rays (uniform origins in
the scene's bounds, uniform directions) straight through embreex on the same Embree scene. The
ratio of the tracer's rays/s to raw rays/s is the overhead of everything that is not Embree.
Records are then written to a photon store on disk (records/s, bytes per record), and one more
process traces 1,000,000 photons to measure peak memory per worker.
"""
from __future__ import annotations

import os
import resource
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pipeline.config import PhotonConfig
from pipeline.photons.raycast import caster_for
from pipeline.photons.tracing import PhotonRange, trace_batch
from pipeline.run.cluster import WORKER_ENV
from pipeline.run.shoot import store_identity
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.builtin import BUILTIN_SCENES, write_builtin
from pipeline.store import PhotonStore

if TYPE_CHECKING:
    from collections.abc import Callable


def _load(scene_path: str):
    scene = read_scene(scene_path)
    return scene, ElementMesh.build(scene)


REPEATS = 3  # tracer and raw Embree alternate this many times; the best time of each counts
TRACER = PhotonConfig(photon_depth=8)  # what is timed: seed 0, paths cut at 8 hits


def _worker(scene_path: str, frame: int, n_photons: int, photon_start: int) -> dict:
    """Trace, then cast raw rays, alternately in this process; best-of-REPEATS timings (the
    machine is shared, so the fastest run is the one least disturbed by other jobs)."""
    scene, elements = _load(scene_path)
    state = scene.pose_frame(frame)
    caster = caster_for(state)
    trace_batch(state, elements, PhotonRange(frame, 10**9, 2000), TRACER)  # warm-up
    trace_s = raw_s = float("inf")
    origins = dirs = None
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        batch = trace_batch(state, elements, PhotonRange(frame, photon_start, n_photons), TRACER)
        trace_s = min(trace_s, time.perf_counter() - t0)
        n_raw = batch.rays_cast
        if origins is None:
            rng = np.random.default_rng(photon_start)
            lo, hi = state.vertices.min(0), state.vertices.max(0)
            origins = (lo + rng.random((n_raw, 3)) * (hi - lo)).astype(np.float32)
            dirs = rng.normal(size=(n_raw, 3))
            dirs = (dirs / np.linalg.norm(dirs, axis=1, keepdims=True)).astype(np.float32)
        t0 = time.perf_counter()
        for lo_i in range(0, n_raw, 1 << 17):  # the tracer's wavefront size
            caster.intersect(origins[lo_i:lo_i + (1 << 17)], dirs[lo_i:lo_i + (1 << 17)])
        raw_s = min(raw_s, time.perf_counter() - t0)
    return {"trace_s": trace_s, "rays": batch.rays_cast, "records": len(batch.key), "raw_s": raw_s,
            "raw_rays": n_raw}


def _memory_worker(scene_path: str, frame: int, n_photons: int, store_url: str) -> dict:
    """Trace and store one frame of ``n_photons``; peak resident memory of this process."""
    scene, elements = _load(scene_path)
    state = scene.pose_frame(frame)
    batch = trace_batch(state, elements, PhotonRange(frame, 0, n_photons), TRACER)
    store = PhotonStore.create(store_url, n_frames=scene.timeline.frames, n_elements=elements.n_elements,
                               frame_numbers=scene.timeline.all_frames(),
                               identity=store_identity(scene.scene_hash, elements.element_size, TRACER),
                               keep_records=True)  # the bytes a record takes on disk are measured
    t0 = time.perf_counter()
    store.write_batch(frame - 1, 0, batch)
    write_s = time.perf_counter() - t0
    batch_dir = Path(store_url) / "frames" / str(frame - 1) / "0"
    on_disk = sum(f.stat().st_size for f in batch_dir.rglob("*") if f.is_file())
    return {"records": len(batch.key), "write_s": write_s, "bytes": on_disk,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def run(scene_names: list[str], *, photons: int, workers: int, memory_photons: int,
        echo: Callable[[str], None]) -> list[dict]:
    os.environ.update(WORKER_ENV)  # inherited by the spawned workers: one thread each
    results = []
    with tempfile.TemporaryDirectory(prefix="loom-bench-") as tmp:
        for name in scene_names:
            path = write_builtin(name, Path(tmp) / f"{name}.glb") if name in BUILTIN_SCENES else Path(name)
            scene, elements = _load(str(path))
            frame = (scene.timeline.frames + 1) // 2
            ctx = get_context("spawn")
            with ProcessPoolExecutor(workers, mp_context=ctx) as pool:
                t0 = time.perf_counter()
                parts = list(pool.map(_worker, [str(path)] * workers, [frame] * workers,
                                      [photons] * workers, [i * photons for i in range(workers)]))
                wall = time.perf_counter() - t0
            with ProcessPoolExecutor(1, mp_context=ctx) as pool:
                mem = pool.submit(_memory_worker, str(path), frame, memory_photons,
                                  str(Path(tmp) / f"{name}.zarr")).result()
            rays_s = sum(p["rays"] / p["trace_s"] for p in parts)
            raw_s = sum(p["raw_rays"] / p["raw_s"] for p in parts)
            row = {
                "scene": name, "elements": elements.n_elements, "triangles": scene.n_triangles,
                "frame": frame, "workers": workers,
                "photons_per_s": sum(photons / p["trace_s"] for p in parts),
                "tracer_rays_per_s": rays_s, "raw_embree_rays_per_s": raw_s, "ratio": rays_s / raw_s,
                "records_per_photon": sum(p["records"] for p in parts) / (photons * workers),
                "records_written_per_s": mem["records"] / mem["write_s"],
                "bytes_per_record_on_disk": mem["bytes"] / max(mem["records"], 1),
                "peak_rss_mb_at_photons": (memory_photons, mem["peak_rss_mb"]),
                "wall_s": wall,
            }
            results.append(row)
            echo(
                f"{name:8s} {elements.n_elements:6d} elements, frame {frame}, {workers} worker(s): "
                f"{row['photons_per_s']:,.0f} photons/s, tracer {rays_s:,.0f} rays/s vs raw Embree "
                f"{raw_s:,.0f} rays/s = {100 * row['ratio']:.0f}%; "
                f"{row['records_written_per_s']:,.0f} records/s written, "
                f"{row['bytes_per_record_on_disk']:.1f} bytes/record on disk (20 raw); "
                f"peak {mem['peak_rss_mb']:.0f} MB per worker at {memory_photons:,} photons")
    return results
