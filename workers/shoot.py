"""The photon task (Dask): trace one (frame, batch) of photons (pipeline/photons/tracing.py) and write
its counts and sums to the photon store."""
from __future__ import annotations

import time

from pipeline.collection.batch_sums import summariser
from pipeline.config import PhotonConfig
from pipeline.photons.tracing import PhotonRange, trace_batch
from pipeline.scene.scene_cache import load_elements, load_scene
from pipeline.store import PhotonStore, counting_io


def shoot_task(*, store_url: str, scene_path: str, scene_hash: str, element_size: float,
               frame: int, frame_index: int, batch: int, n_photons: int, photon_start: int,
               seed: int, max_depth: int) -> dict:
    """Dask task: trace (frame, batch) and write its counts and sums (and its records, if the store
    keeps them) to the photon store; skip it if done.

    Plain arguments in, a small dict of counters out; runs the same with or without a cluster.
    """

    store = PhotonStore.open_shared(store_url, mode="r+")
    if store.is_done(frame_index, batch):
        return {"frame": frame, "batch": batch, "skipped": True}
    t0 = time.perf_counter()
    scene = load_scene(scene_path, scene_hash)
    elements = load_elements(scene_path, scene_hash, element_size)
    state = scene.pose_frame(frame)
    t1 = time.perf_counter()
    result = trace_batch(state, elements, PhotonRange(frame, photon_start, n_photons),
                         PhotonConfig(element_size=element_size, seed=seed, photon_depth=max_depth))
    t2 = time.perf_counter()
    summed, summary = [0.0], summariser(elements)

    def summarise(*records):  # the gather's batch sums, made while the records are in memory
        t = time.perf_counter()
        out = summary(*records)
        summed[0] += time.perf_counter() - t
        return out

    with counting_io() as io:
        store.write_batch(frame_index, batch, result, summarise=summarise)
    t3 = time.perf_counter()
    return {"frame": frame, "batch": batch, "skipped": False, "photons": n_photons,
            "records": len(result.key), "rays": result.rays_cast, "capped": result.stats["capped"],
            "pose_s": t1 - t0, "trace_s": t2 - t1, "write_s": t3 - t2 - summed[0], "sums_s": summed[0],
            **{f"shoot_{k}": v for k, v in io.items()}}
