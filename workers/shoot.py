"""The photon task (Dask): trace one (frame, batch) of photons (pipeline/photons/tracing.py) and write
its counts and sums to the photon store."""
from __future__ import annotations

import time
from dataclasses import dataclass

from pipeline.collection.batch_sums import summariser
from pipeline.config import PhotonConfig
from pipeline.photons.tracing import PhotonRange, trace_batch
from pipeline.scene.scene_cache import SceneRef
from pipeline.store import PhotonStore, counting_io


@dataclass(frozen=True)
class ShootRequest:
    """Batch ``batch`` of frame ``photons.frame``: ``photons`` traced with ``config``'s seed and
    depth cap in ``scene``, written to the store at ``store_url``."""

    scene: SceneRef
    store_url: str
    batch: int
    photons: PhotonRange
    config: PhotonConfig


def shoot_task(request: ShootRequest) -> dict:
    """Dask task: trace the request's batch and write its counts and sums (and its records, if the
    store keeps them) to the photon store; skip it if done.

    A frozen request in, a small dict of counters out; runs the same with or without a cluster.
    """
    frame, batch, n_photons = request.photons.frame, request.batch, request.photons.count
    store = PhotonStore.open_shared(request.store_url, mode="r+")
    if store.is_done(frame - 1, batch):
        return {"frame": frame, "batch": batch, "skipped": True}
    t0 = time.perf_counter()
    scene, elements = request.scene.scene(), request.scene.elements()
    state = scene.pose_frame(frame)
    t1 = time.perf_counter()
    result = trace_batch(state, elements, request.photons, request.config)
    t2 = time.perf_counter()
    summed, summary = [0.0], summariser(elements)

    def summarise(*records):  # the gather's batch sums, made while the records are in memory
        t = time.perf_counter()
        out = summary(*records)
        summed[0] += time.perf_counter() - t
        return out

    with counting_io() as io:
        store.write_batch(frame - 1, batch, result, summarise=summarise)
    t3 = time.perf_counter()
    return {"frame": frame, "batch": batch, "skipped": False, "photons": n_photons,
            "records": len(result.key), "rays": result.rays_cast, "capped": result.stats["capped"],
            "pose_s": t1 - t0, "trace_s": t2 - t1, "write_s": t3 - t2 - summed[0], "sums_s": summed[0],
            **{f"shoot_{k}": v for k, v in io.items()}}
