"""The photon-shooting stage: plan (frame, batch) tasks, fan them out, record what is shared.

Frames with equal state key (camera-only motion) share one photon set: the first frame of the
timeline with that key is traced, and the others are recorded as its sharers in the store
(`PhotonStore.share_frame`). A frame's photons arrive in batches: shooting N photons for a frame
that already holds D < N adds one batch of N - D (N_frame doubles in §5.2.3); a frame with D >= N
needs nothing. Every task is skipped when its batch is already done, so a rerun resumes.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

from pipeline.config import PhotonConfig
from pipeline.errors import LoomError
from pipeline.paths import check_writable_dir
from pipeline.photons.tracing import PhotonRange
from pipeline.scene import ElementMesh, Scene
from pipeline.scene.environment import EnvironmentMap
from pipeline.scene.scene_cache import SceneRef
from pipeline.store import PhotonStore, StoreIdentity, remove_partials
from workers.shoot import ShootRequest, shoot_task

from .cluster import connect, run_tasks, task_key


@dataclass
class ShootPlan:
    scene: Scene
    elements: ElementMesh
    frames: list[int]  # requested frames
    sources: dict[int, int]  # frame -> frame whose photons it uses (itself when traced)
    config: PhotonConfig
    n_photons: int

    @property
    def traced_frames(self) -> list[int]:
        return sorted({self.sources[f] for f in self.frames})


def check_store_location(url: str) -> None:
    """Refuse a store location we cannot write before anything is traced or written."""
    if "://" in url and not url.startswith("file://"):
        return  # remote stores are checked by zarr when created
    check_writable_dir(url[len("file://"):] if url.startswith("file://") else url, field="--store")


def plan(scene: Scene, frames_spec: str | None, n_photons: int, config: PhotonConfig) -> ShootPlan:
    """The frames of ``frames_spec`` to give ``n_photons`` each, traced with ``config``, and whose
    photons each frame uses; a bad count or frame list is a one-line LoomError."""
    if not isinstance(n_photons, int) or n_photons <= 0:
        raise LoomError(f"must be a positive number of photons per frame, got {n_photons}", field="--photons")
    try:
        frames = scene.timeline.select(frames_spec)
    except LoomError as err:  # name the file and where its timeline comes from
        tl = scene.timeline
        span = f"{tl.frames} frame(s) at {tl.fps:g} fps, {tl.duration:g} s"
        if not scene.has_animation:
            span += "; the file has no animation"
        raise LoomError(f"{err.reason} ({span})", path=str(scene.path), field=err.field) from None
    elements = ElementMesh.build(scene, config.element_size)
    keys = scene.frame_state_keys
    first_with_key: dict[str, int] = {}
    for f, k in zip(scene.timeline.all_frames(), keys):
        first_with_key.setdefault(k, f)
    sources = {f: first_with_key[keys[f - 1]] for f in scene.timeline.all_frames()}
    return ShootPlan(scene, elements, frames, sources, config, n_photons)


def open_store(p: ShootPlan, url: str, *, keep_records: bool) -> PhotonStore:
    """Create (or reopen, refusing another scene, config or ``keep_records``) the run's store and
    record sharing."""
    tl = p.scene.timeline
    store = PhotonStore.create(
        url, n_frames=tl.frames, n_elements=p.elements.n_elements, frame_numbers=tl.all_frames(),
        identity=store_identity(p.scene.scene_hash, p.elements.element_size, p.config), keep_records=keep_records)
    for f in p.frames:
        src = p.sources[f]
        if src != f and store.source_frame(f - 1) != src - 1:
            store.share_frame(f - 1, src - 1)
    return store


def store_identity(scene_hash: str, element_size: float, config: PhotonConfig) -> StoreIdentity:
    """What the run's photons are made from: a store of another scene, photon settings or seed is refused."""
    return StoreIdentity(scene_hash, config.photon_hash(element_size), config.seed)


def shoot_key(config: PhotonConfig, element_size: float, frame: int, batch: int, store_url: str) -> str:
    """The Dask key of photon batch ``batch`` of ``frame`` shot into ``store_url``."""
    name = f"shoot-{config.photon_hash(element_size)[:8]}-s{config.seed}-f{frame:05d}-b{batch:02d}"
    return task_key(name, store_url)


def tasks(p: ShootPlan, store: PhotonStore, url: str) -> list[tuple[str, ShootRequest]]:
    """(key, request) of every batch still to trace."""
    env = p.scene.sky.source if isinstance(p.scene.sky, EnvironmentMap) else None
    scene = SceneRef(str(p.scene.path), p.scene.scene_hash, None, p.elements.element_size, p.scene.animation_option,
                     p.scene.variant_option, env)
    out = []
    for f in p.traced_frames:
        done = store.done_batches(f - 1)
        have = store.photons_emitted(f - 1)
        if have >= p.n_photons:
            continue
        batch = len(done)
        out.append((shoot_key(p.config, p.elements.element_size, f, batch, url),
                    ShootRequest(scene, url, batch, PhotonRange(f, have, p.n_photons - have), p.config)))
    return out


def shoot(p: ShootPlan, store_url: str, *, keep_records: bool = False, scheduler: str = "local",
          workers: int | None = None, progress: bool = True) -> dict:
    """Trace the photons of every frame of the plan ``p`` into the store at ``store_url``; returns a
    summary of the run. ``keep_records`` stores the raw hit records beside the counts and sums."""
    check_store_location(store_url)
    t0 = time.perf_counter()
    # The cluster is up before the store is created: a scheduler that cannot start or be reached
    # leaves no empty store behind
    with connect(scheduler, workers) as client:
        store = open_store(p, store_url, keep_records=keep_records)
        todo = tasks(p, store, store_url)
        results = run_tasks(client, shoot_task, todo, desc="shoot", progress=progress) if todo else {}
    remove_partials(store_url)  # every batch is written: what killed writers left can go
    elapsed = time.perf_counter() - t0
    traced = [r for r in results.values() if not r.get("skipped")]
    return {
        "frames": len(p.frames), "traced_frames": len(p.traced_frames),
        "shared_frames": sum(1 for f in p.frames if p.sources[f] != f),
        "tasks": len(todo), "skipped": len(p.traced_frames) - len(traced),
        "photons": sum(r["photons"] for r in traced), "records": sum(r["records"] for r in traced),
        "rays": sum(r["rays"] for r in traced), "seconds": elapsed,
    }
