"""The segment coordinator: the five steps of §5.2 for one animation segment, as a Dask task.

``coordinate`` (in the client) runs one :func:`segment_task` per segment, in segment order as the
paper does: segment i+1 starts after segment i's end with its F_max. Each segment task fans out
its own photon batches, reconstruction and frame tasks from inside the task through distributed's
``worker_client`` (which secedes from the worker's thread pool, so even one one-thread worker
cannot deadlock); with ``--scheduler synchronous`` the same code runs them in-process. Task i:

1. Steps 1-3 for segment i if no task decided it yet (i = 0, or a stale record), then for segment
   i + 1, whose photons segment i's windows reach (§5.2: "Steps 1-3 are performed not only for the
   current segment but for the subsequent segment as well"); the previous segment's photons are
   in the store already.
   - Step 1 (§5.2.1): a pilot of ``pilot_photons`` at K gives the energy-based error E of its
     indirect map; N_frame from Eq. (2) for E ~ E_max sqrt(F_max + 1); every frame gets N_frame.
   - Step 2 (§5.2.2): p_me both ways at K; F_max grows while p_me >= p_thr, K moving with it.
   - Step 3 (§5.2.3): I1(K), I2(K) from the even and odd photons with adaptive collection,
     composited with the same camera samples and direct light, tone mapped as the final frame
     (pipeline/frames/perceived.py); N_frame starts on a rung of the cap's halvings and doubles (one
     batch more a frame) while d_AQM > d_thr (segments.ladder_n_frame, next_n_frame).
   - Frames within F_max/2 of an animation end get ``end_photons`` x N_frame (§5.2).
2. Steps 4-5 (§5.2.4-5) for the frames of segment i: reconstruction tasks of ``CHUNK_FRAMES``
   frames each (workers/reconstruct.reconstruct_task), then one composite task a frame.

The decisions are pure functions in pipeline/segments/decisions.py. Records (pipeline/segments/records.py)
are written when a segment is decided and when it is done; a rerun skips done segments whose
frames are valid and reuses every stored photon batch. Which photons a frame uses is fixed by the
records (the fewest leading batches holding its target), never by what else the store holds, so
results do not depend on the order work happened in, on the worker count or on a resume.
"""
from __future__ import annotations

import math
import time
from contextlib import contextmanager
from dataclasses import dataclass, fields
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterable, Iterator

import numpy as np
from distributed import get_worker, worker_client

from pipeline.aqm.visualize import difference_picture
from pipeline.collection.estimators import vertex_moments
from pipeline.collection.maps import (
    MapRequest,
    WindowSpec,
    collection_windows,
    illumination_maps,
    step_regions,
    window_counts,
)
from pipeline.config import RenderConfig, stable_digest
from pipeline.errors import LoomError
from pipeline.frames.camera_paths import render_frame, visible_adaptation
from pipeline.frames.images import frame_is_valid, frame_paths, write_png
from pipeline.frames.perceived import camera_flow, displayed_difference
from pipeline.frames.tonemap import adapt_in_time
from pipeline.photons.tracing import PhotonRange, trace_batch
from pipeline.scene.scene_cache import load_elements, load_scene
from pipeline.segments.decisions import (
    Placement,
    calibrated_start,
    doubling_loop,
    energy_error,
    fmax_loop,
    ladder_n_frame,
    needed_n_frame,
    p_me,
    photon_targets,
    pilot_n_frame,
    place_segment,
)
from pipeline.segments.records import DIRECTORY, SegmentRecord, read_record, record_index, record_path, write_record
from pipeline.store import PhotonStore
from workers.composite import composite_task
from workers.reconstruct import reconstruct_task
from workers.shoot import shoot_task

from .cluster import TASK_RETRIES, completed, group_sizes, run_tasks, submit_grouped, task_key
from .cluster import result as wait_result
from .settings import RenderSettings
from .shoot import shoot_key, store_identity

if TYPE_CHECKING:
    from distributed import Client

    from pipeline.scene import ElementMesh, Scene

CHUNK_FRAMES = 16  # frames per reconstruction task: fixed, so the gather's bits never depend on workers
# Frames per photon-batch task and per composite task at most (pipeline/run/cluster.py group_sizes,
# whose groups shrink to single frames at the end of a run): ROOM's batches take about 0.06 s and
# its composites 0.17 s a frame, against 8 ms of Dask's own CPU a task.
SHOOT_GROUP, COMPOSITE_GROUP = 8, 4


@dataclass(frozen=True)
class Job:
    """Everything a segment task needs. It travels to workers pickled (frozen dataclasses all
    through); :meth:`to_dict` and :meth:`from_dict` are its plain-JSON form (plan.json, the report)."""

    scene_path: str
    scene_hash: str
    camera: str | None  # the --camera option (None: the scene's first camera)
    camera_name: str  # the camera node rendered from
    element_size: float
    store_url: str
    out_dir: str
    first: int  # first and last frame of the animation the segments cover
    last: int
    selection: tuple  # frames to render (fixed settings may skip frames; guided: first..last)
    settings: RenderSettings  # resolution, spp, reflection depth, area samples, tone mapping
    config: RenderConfig
    render_hash: str  # what a frame's pixels depend on besides its maps and adaptation
    decision_hash: str  # what the segment decisions depend on
    fmax: int  # F_max of the first segment (--fmax or fmax_initial), or of every frame when fixed
    n_photons: int | None  # None: guided (--photons auto); else fixed N_frame
    temporal: str  # adaptive | fixed | off
    single_state: bool  # camera-only motion: every frame shares one photon set

    def to_dict(self) -> dict:
        return {f.name: (getattr(self, f.name).to_dict() if f.name in ("settings", "config") else getattr(self, f.name))
                for f in fields(self)}

    @classmethod
    def from_dict(cls, data: dict) -> Job:
        return cls(**{**data, "selection": tuple(data["selection"]),
                      "settings": RenderSettings.from_dict(data["settings"]),
                      "config": RenderConfig.from_dict(data["config"])})


@contextmanager
def fanout() -> Iterator[object | None]:
    """A client for tasks submitted from inside a task (worker_client, which secedes), or None
    when not on a Dask worker (synchronous scheduler): run_tasks then runs them in-process."""
    try:
        get_worker()
    except ValueError:  # not on a Dask worker
        yield None
        return
    with worker_client() as client:
        yield client


@contextmanager
def _writing(where: str):
    """A task's failure to write (permissions, a full or read-only disk, a path that is a file) is
    the user's to fix: one line naming the file, instead of a worker's traceback."""
    try:
        yield
    except OSError as err:
        raise LoomError(f"cannot write: {err.strerror or err}", path=err.filename or where, field="store") from None


PROGRESS_TOPIC = "loom-progress"
_local_progress: list = []  # callbacks of a client running segment tasks in-process (synchronous)


def progress(message: str) -> None:
    """A progress line from a segment task: a worker event the client subscribed to, or the local
    callback when the task runs in the client's process."""
    try:
        get_worker().log_event(PROGRESS_TOPIC, message)
    except ValueError:  # not on a Dask worker
        for callback in _local_progress:
            callback(message)


class SegmentRun:
    """One segment task's view of the run: scene, element mesh, store, config, records."""

    def __init__(self, job: Job, client: Client | None):
        self.job, self.client = job, client
        self.config = job.config
        # A store swapped for another run's (another scene, photon settings or seed) is refused here
        self.store = PhotonStore.open(job.store_url, mode="r+",
                                      identity=store_identity(job.scene_hash, job.element_size, self.config.photons))
        self.times = {"shoot_s": 0.0, "aqm_s": 0.0, "temporal_s": 0.0}
        self.io_bytes: dict[str, int] = {}  # what the tasks read and wrote (store.counting_io)
        self.batches_traced = 0
        self._index = None  # the segment being decided, for progress lines
        self._windows_at_k: dict = {}  # Fig. 5 at K of the segment being decided (its last d_AQM step)

    # Loaded when first used, not before the first tasks go out: a fixed render's coordinator never
    # needs them, and its worker's first photon batch loads them into the process's cache anyway
    @cached_property
    def scene(self) -> Scene:
        return load_scene(self.job.scene_path, self.job.scene_hash, self.job.camera)

    @cached_property
    def elements(self) -> ElementMesh:
        return load_elements(self.job.scene_path, self.job.scene_hash, self.job.element_size)

    def workers(self) -> list[str]:
        """Addresses of the cluster's workers now, sorted (none without a cluster)."""
        return sorted(self.client.scheduler_info().get("workers", {})) if self.client is not None else []

    def add_times(self, result: dict, keys: Iterable[str]) -> None:
        """Sum a task's own timings (seconds of work, whichever worker did it) into this segment's,
        and its byte counts (keys ending ``_bytes``) into ``io_bytes``."""
        for k in keys:
            if k.endswith("_bytes") and k in result:
                self.io_bytes[k] = self.io_bytes.get(k, 0) + int(result[k])
            elif k in result:
                self.times[f"task_{k}"] = self.times.get(f"task_{k}", 0.0) + float(result[k])

    # --- photons ---------------------------------------------------------------------------
    def shoot(self, targets: dict[int, int]) -> None:
        """Trace one batch more for every frame whose stored batches hold fewer than its target."""
        t0 = time.perf_counter()
        sources = self.store.source_frames()
        want: dict[int, int] = {}  # per source frame (1-based)
        for f, n in targets.items():
            src = int(sources[f - 1]) + 1
            want[src] = max(want.get(src, 0), int(n))
        prefix = self.store.prefixes_for({f - 1: n for f, n in want.items()})
        short = [f for f in sorted(want) if prefix[f - 1] is None]
        emitted, n_done = (self.store.emitted(), self.store.batches_per_frame()) if short else (None, None)
        calls = []
        for f in short:
            n, have, batch = want[f], int(emitted[f - 1]), int(n_done[f - 1])
            key = shoot_key(self.config.photons, self.job.element_size, f, batch, self.job.store_url)
            calls.append((key, dict(
                store_url=self.job.store_url, scene_path=self.job.scene_path, scene_hash=self.job.scene_hash,
                element_size=self.job.element_size, frame=f, frame_index=f - 1, batch=batch,
                n_photons=n - have, photon_start=have, seed=self.config.photons.seed,
                max_depth=self.config.photons.photon_depth)))
        with _writing(self.job.store_url):
            results = run_tasks(self.client, shoot_task, calls, desc="shoot", progress=False,
                                group=group_sizes(len(calls), len(self.workers()), SHOOT_GROUP))
        for r in results.values():
            self.add_times(r, ("pose_s", "trace_s", "write_s", "sums_s", "shoot_read_bytes", "shoot_write_bytes"))
        self.batches_traced += len(calls)
        self.times["shoot_s"] += time.perf_counter() - t0

    def batches(self, targets: dict[int, int]) -> np.ndarray:
        """(n_frames,) leading batches in use per store frame for these targets (0 elsewhere)."""
        use = np.zeros(self.store.n_frames, np.int64)
        prefix = self.store.prefixes_for({f - 1: n for f, n in targets.items()})
        for f, n in targets.items():
            nb = prefix[f - 1]
            if nb is None:
                raise RuntimeError(f"frame {f} holds fewer than its {n} photons")
            use[f - 1] = nb
        return use

    def reach_targets(self, rec: SegmentRecord) -> dict[int, int]:
        """Photon targets of every frame segment ``rec``'s windows may reach: the earlier segments',
        its own and the next one's (§5.2: a segment's photons are collected by its neighbours)."""
        if not rec.guided:
            return {f: self.job.n_photons for f in self.job.selection}
        out = {**self.known_targets(rec.index), **rec.targets()}
        after = read_record(self.job.out_dir, rec.index + 1)
        if after is not None and after.decision_hash == self.job.decision_hash:
            out.update(after.targets())
        return out

    def known_targets(self, index: int) -> dict[int, int]:
        """Targets of every decided segment before ``index`` (their photons are in the store)."""
        out: dict[int, int] = {}
        for i in range(index):
            rec = read_record(self.job.out_dir, i)
            if rec is not None:
                out.update(rec.targets())
        return out

    # --- Step 1 ------------------------------------------------------------------------------
    def pilot(self, place: Placement) -> dict:
        """Step 1's probe, traced here in memory, never stored: its photons are the first
        ``pilot_photons`` of frame K's own stream (counter-based), so the frame's batches hold them
        anyway. Stored, it was one more batch at every K and one more wave of tasks a segment (docs/07-segments.md
        §2); read back from the store when K happened to be
        traced, E would depend on what else ran first."""
        n_probe = self.config.segments.pilot_photons
        t0 = time.perf_counter()
        batch = trace_batch(self.scene.pose_frame(place.k), self.elements, PhotonRange(place.k, 0, n_probe),
                            self.config.photons)
        s, q = vertex_moments(*batch.indirect(), self.elements.element_vertices, self.elements.n_vertices)
        self.times["shoot_s"] += time.perf_counter() - t0
        e0 = energy_error(s, q)
        n_pilot = pilot_n_frame(n_probe, e0, self.config.segments.e_max, place.fmax)
        progress(f"segment {self._index}: pilot at K {place.k}: E {e0:.3f} with {n_probe:,} "
                 f"photons -> N_frame {n_pilot:,.0f} (Eq. 2, F_max {place.fmax})")
        return {"frame": place.k, "n_probe": int(n_probe), "e_probe": e0,
                "e_target": self.config.segments.e_max * float(np.sqrt(place.fmax + 1)),
                "n_pilot": n_pilot if np.isfinite(n_pilot) else None}

    # --- Step 2 ------------------------------------------------------------------------------
    def p_me(self, place: Placement, targets: dict[int, int]) -> tuple[float, float]:
        use = self.batches(targets)
        counts = window_counts(self.store, batches=use)
        emitted = np.array([self.store.photons_in(f, int(use[f])) for f in range(self.store.n_frames)], np.float64)
        # p_me counts how far Condition (1)'s walks reach each way; a regional step stops a walk as
        # it stops the collection (pipeline/collection/regional_steps.py)
        back, fwd = collection_windows(counts, emitted, [place.k - 1], WindowSpec("adaptive", place.fmax),
                                       self.config.collection,
                                       regions=step_regions(self.elements, self.config.collection))
        hit = counts[place.start - 1:place.end].sum(axis=0) > 0
        pb, pf = p_me(back[0], fwd[0], place.fmax, hit)
        progress(f"segment {self._index}: F_max {place.fmax}, K {place.k}: p_me {pb:.2f} back, {pf:.2f} forward")
        return pb, pf

    # --- Step 3 ------------------------------------------------------------------------------
    def d_aqm(self, place: Placement, targets: dict[int, int], index: int, temporal: str) -> float:
        """d_AQM (percent) of I1(K) against I2(K) as the viewer sees them; the M_AQM picture is
        written beside the segment record."""
        t0 = time.perf_counter()
        use = self.batches(targets)
        k = place.k
        # Each half is reconstructed as the final frame will be, spatial filter included (Step 5):
        # on ATRIUM's 43,000 small elements the filter, not N_frame, removes most of what the
        # unfiltered halves differ by; judged unfiltered, the loop would trace for noise no frame shows.
        (lit,) = illumination_maps(self.store, self.elements, self.scene,
                                   MapRequest(WindowSpec(temporal, place.fmax), [k - 1], batches=use, halves=True),
                                   self.config.collection, self.config.filter)
        state = self.scene.pose_frame(k)
        job, px = self.job, self.job.settings
        # both halves along one set of camera paths: the bits of two renders at the cost of one
        img = render_frame(state, self.elements, lit.irradiance[0], width=px.width, height=px.height, spp=px.spp,
                           seed=self.config.photons.seed, frame=k, max_depth=px.reflection_depth,
                           area_samples=px.area_samples, also_maps=lit.irradiance[1:])
        images = [img.beauty, img.also_beauty(0)]
        # L_wa as the frame's own (reconstruct_task): what the camera sees of the halves' mean map
        adaptation = visible_adaptation(state, self.elements, 0.5 * (lit.irradiance[0] + lit.irradiance[1]),
                                        aspect=px.width / px.height, seed=self.config.photons.seed,
                                        max_depth=px.reflection_depth, area_samples=px.area_samples)
        params = px.tonemap
        flow = camera_flow(self.scene, k, px.width, px.height, params)
        result = displayed_difference(images[0], images[1], adaptation, params=params,
                                      aqm_size=self.config.segments.aqm_size, flow=flow)
        counts = window_counts(self.store, batches=use)[place.start - 1:place.end]
        self._windows_at_k = window_histogram(lit.back, lit.fwd, place.fmax, counts)
        picture = record_path(job.out_dir, index).with_suffix(".aqm.png")
        picture.parent.mkdir(parents=True, exist_ok=True)
        write_png(picture, difference_picture(images[0], result.visible))
        self.times["aqm_s"] += time.perf_counter() - t0
        progress(f"segment {index}: N_frame {targets[k]:,} at K {k}: d_AQM {result.d_aqm:.2f} %")
        return float(result.d_aqm)

    # --- Steps 1-3 for one segment -----------------------------------------------------------
    def decide(self, index: int, start: int, fmax: int) -> SegmentRecord:
        job, cfg = self.job, self.config.segments
        self._index, self._windows_at_k = index, {}
        t_start = time.perf_counter()
        if job.n_photons is not None:  # fixed settings: nothing to decide
            return self._fixed_record(index)
        prior = self.known_targets(index)
        if job.single_state:  # camera-only motion: one photon set, nothing to collect in time
            place = Placement(job.first, (job.first + job.last) // 2, job.last, 0)
        else:
            place = place_segment(start, fmax, job.last)

        # Step 1: pilot at K, N_frame from Eq. (2)
        pilot = self.pilot(place)
        before = read_record(job.out_dir, index - 1) if index else None
        carried = ((before.pilot.get("n_pilot"), needed_n_frame(before.n_frame, before.n_frame_steps,
                                                               before.capped, cfg.d_thr))
                   if before is not None and before.guided and before.pilot.get("n_pilot") else None)
        start_n = calibrated_start(pilot["n_pilot"] if pilot["n_pilot"] is not None else float("inf"), carried)
        pilot["n_start"] = start_n if math.isfinite(start_n) else None
        n = ladder_n_frame(start_n, cfg.n_frame_min, cfg.n_frame_max)
        t_init = time.perf_counter()

        # Step 2: F_max while p_me >= p_thr (never for camera-only motion: all frames share photons)
        def p_me_of(at: Placement) -> tuple[float, float]:
            self.shoot({f: n for f in at.frames})
            return self.p_me(at, {**prior, **{f: n for f in at.frames}})

        temporal = "off" if job.single_state else job.temporal
        if job.single_state:
            fmax_steps = []
        else:
            place, fmax_steps = fmax_loop(place.start, place.fmax, job.last, p_me_of, p_thr=cfg.p_thr,
                                          step=cfg.fmax_step, cap=cfg.fmax_cap)
        t_fmax = time.perf_counter()

        # Step 3: N_frame doubled while d_AQM > d_thr
        def d_aqm_of(n_frame: int) -> float:
            self.shoot({f: n_frame for f in place.frames})
            return self.d_aqm(place, {**prior, **{f: n_frame for f in place.frames}}, index, temporal)

        n, n_steps, capped = doubling_loop(n, d_aqm_of, d_thr=cfg.d_thr, n_max=cfg.n_frame_max)
        t_n = time.perf_counter()

        # Frames next to an animation end: more photons for their missing neighbours (§5.2)
        final = photon_targets(place, n, first=job.first, last=job.last, end_factor=cfg.end_photons)
        self.shoot(final)
        ends = sorted(f for f, v in final.items() if v != n)
        rec = SegmentRecord(
            index=index, start=place.start, end=place.end, k=place.k, fmax=place.fmax, n_frame=n,
            temporal=temporal, guided=True, decision_hash=job.decision_hash, end_frames=ends,
            end_factor=cfg.end_photons, pilot=pilot, fmax_steps=fmax_steps, n_frame_steps=n_steps, capped=capped,
            windows_at_k=self._windows_at_k,
            times_s={"init_s": t_init - t_start, "fmax_s": t_fmax - t_init, "n_frame_s": t_n - t_fmax,
                     "decide_s": time.perf_counter() - t_start})
        write_record(job.out_dir, rec)
        return rec

    def _fixed_record(self, index: int) -> SegmentRecord:
        """--photons N --fmax F: one record over the render's frames, shot at N."""
        job = self.job
        t0 = time.perf_counter()
        self.shoot({f: job.n_photons for f in job.selection})
        rec = SegmentRecord(index=index, start=job.first, end=job.last, k=(job.first + job.last) // 2,
                            fmax=job.fmax, n_frame=job.n_photons, temporal=job.temporal, guided=False,
                            decision_hash=job.decision_hash, times_s={"init_s": time.perf_counter() - t0})
        write_record(job.out_dir, rec)
        return rec

    def record(self, index: int, start: int, fmax: int) -> SegmentRecord:
        """Segment ``index`` decided for this run: its record if current, else decided now."""
        rec = read_record(self.job.out_dir, index)
        if rec is not None and rec.decision_hash == self.job.decision_hash and rec.start == start:
            return rec
        return self.decide(index, start, fmax)

    # --- Steps 4-5 and the frames --------------------------------------------------------------
    def frames_of(self, rec: SegmentRecord) -> list[int]:
        sel = set(self.job.selection)
        return [f for f in range(rec.start, rec.end + 1) if f in sel]

    def reconstruct_calls(self, rec: SegmentRecord, targets: dict[int, int]) -> list[tuple[str, dict]]:
        """One reconstruction task per chunk of :func:`frame_chunks` of the segment's frames."""
        job, px = self.job, self.job.settings
        use = self.batches(targets).tolist()
        return [(task_key(f"reconstruct-{job.decision_hash[:8]}-f{chunk[0]:05d}", job.store_url), dict(
            store_url=job.store_url, scene_path=job.scene_path, scene_hash=job.scene_hash, camera=job.camera,
            element_size=job.element_size, frames=chunk, fmax=rec.fmax, mode=rec.temporal,
            batches=use, config=job.config, aspect=px.width / px.height, max_depth=px.reflection_depth,
            area_samples=px.area_samples))
            for chunk in frame_chunks(self.frames_of(rec))]

    def _took(self, result: dict) -> None:
        self.add_times(result.get("times", {}), result.get("times", {}).keys())

    def reconstruct(self, rec: SegmentRecord, targets: dict[int, int]) -> dict:
        """Steps 4-5 for the frames of ``rec`` (maps written); their frame infos."""
        t0 = time.perf_counter()
        out = {}
        for r in run_tasks(self.client, reconstruct_task, self.reconstruct_calls(rec, targets), desc="reconstruct",
                           progress=False).values():
            out.update(r["frames"])
            self._took(r)
        self.times["temporal_s"] += time.perf_counter() - t0
        return out

    def frames(self, rec: SegmentRecord, targets: dict[int, int], before: dict[int, dict],
               force: bool) -> tuple[dict, dict]:
        """Steps 4-5 and the composites of a segment's frames, pipelined: a chunk's frames are
        composited as soon as it and every chunk before it are reconstructed (the smoothed
        adaptation looks only backwards), so ray tracing overlaps the temporal stage. Returns the
        frame infos and the composite results of the frames written. ``before``: infos of the
        frames of earlier segments; ``force``: write every frame of the segment."""
        t0 = time.perf_counter()
        calls = self.reconstruct_calls(rec, targets)
        forced = frozenset(self.frames_of(rec)) if force else frozenset()
        info, out, written = dict(before), {}, {}

        def take(result: dict, chunk_frames: list[int]) -> list[tuple[str, dict]]:
            self._took(result)
            out.update(result["frames"])
            info.update({int(f): v for f, v in result["frames"].items()})
            return composite_calls(self.job, chunk_frames, info, force=forced)

        if self.client is None:
            for _, kw in calls:
                for _, ckw in take(reconstruct_task(**kw), kw["frames"]):
                    r = composite_task(**ckw)
                    written[int(r["frame"])] = r
            self.times["temporal_s"] += time.perf_counter() - t0
            return out, written
        submit = self.client.submit
        # Consecutive chunks share the frames their windows reach: contiguous runs of chunks go to
        # one worker each (a hint, so the batch-sums cache of pipeline/collection/batch_sums.FrameSums hits;
        # Dask may still move a chunk, and placement never changes a bit of the result)
        workers = self.workers()
        # Priorities: a worker takes its chunks in frame order (so composites can follow chunk by
        # chunk and its batch-sums cache sees the frames of the chunk before) and any reconstruction
        # before any composite (the temporal stage is not slowed by the ray tracing it feeds).
        chunk_of = {submit(reconstruct_task, key=key, retries=TASK_RETRIES, pure=False, priority=len(calls) - i,
                           workers=[workers[i * len(workers) // len(calls)]] if workers else None,
                           allow_other_workers=True, **kw): i
                    for i, (key, kw) in enumerate(calls)}
        ready, following, composites = {}, 0, {}
        for future, result in completed(self.client, list(chunk_of)):
            ready[chunk_of[future]] = result
            while following in ready:
                todo = take(ready.pop(following), calls[following][1]["frames"])
                left = sum(len(kw["frames"]) for _, kw in calls[following:])  # the segment's frames from here
                composites.update(submit_grouped(self.client, composite_task, todo, group_sizes(
                    len(todo), len(workers), COMPOSITE_GROUP, left=left), priority=0))
                following += 1
        self.times["temporal_s"] += time.perf_counter() - t0
        for _, results in completed(self.client, composites):
            written.update((int(r["frame"]), r) for r in results)
        return out, written


def frame_chunks(frames: list[int], size: int = CHUNK_FRAMES) -> list[list[int]]:
    """``frames`` (ascending) in chunks of at most ``size`` consecutive frame numbers, a new chunk
    at every gap: a chunk's gather reads the photons of every frame from its first window's start
    to its last one's end, and a frame list (``--frames 1,40,80``) traces only the frames it names."""
    chunks: list[list[int]] = []
    for f in frames:
        if chunks and len(chunks[-1]) < size and f == chunks[-1][-1] + 1:
            chunks[-1].append(f)
        else:
            chunks.append([f])
    return chunks


def window_histogram(back: np.ndarray, fwd: np.ndarray, fmax: int, counts: np.ndarray) -> dict:
    """Fig. 5: how many elements collect 0..F_max/2 frames back and forward at K, over the elements
    some photon of the segment hit (``counts``: (frames, E) records; never-hit ones say nothing)."""
    hit = counts.sum(axis=0) > 0
    half = max(int(fmax) // 2, int(back.max(initial=0)), int(fwd.max(initial=0)))
    return {"back": np.bincount(back[hit].astype(np.int64), minlength=half + 1).tolist(),
            "fwd": np.bincount(fwd[hit].astype(np.int64), minlength=half + 1).tolist(),
            "elements": int(hit.sum()), "fmax": int(fmax)}


def frame_hash(render_hash: str, info: dict, adaptation: float) -> str:
    """What a frame's files depend on: the render's settings, its indirect map and its exposure."""
    return stable_digest({"render": render_hash, "map": info["digest"], "adaptation": float(adaptation)})


def smoothed_adaptation(job: Job, frames_info: dict[int, dict], upto: int) -> dict[int, float]:
    """The eye's adaptation L_a of each rendered frame up to ``upto``: the time course of
    pipeline/frames/tonemap.py (adapt_in_time) over the frames' own L_wa in the records, at the timeline's
    times. It is causal, so a segment's frames need only the L_wa of the frames before them."""
    scene = load_scene(job.scene_path, job.scene_hash, job.camera)
    frames = [f for f in job.selection if f <= upto]
    values = adapt_in_time([frames_info[f]["adaptation"] for f in frames],
                           [scene.timeline.time(f) for f in frames], job.settings.tonemap)
    return dict(zip(frames, values.tolist()))


def composite_frames(job: Job, client: Client | None, frames: list[int], frames_info: dict[int, dict], *,
                     force: frozenset = frozenset()) -> dict[int, dict]:
    """Composite every frame of ``frames`` whose files do not carry its current frame hash (and
    those in ``force``); returns the composite task's result (rays per kind, timings) of every frame
    written."""
    done = run_tasks(client, composite_task, composite_calls(job, frames, frames_info, force=force),
                     desc="composite", progress=False)
    return {int(r["frame"]): r for r in done.values()}


def composite_calls(job: Job, frames: list[int], frames_info: dict[int, dict], *,
                    force: frozenset = frozenset()) -> list[tuple[str, dict]]:
    """(key, kwargs) of the composite tasks of the frames in ``frames`` that need one (see
    :func:`composite_frames`); ``frames_info`` holds every rendered frame up to the last of them."""
    smoothed = smoothed_adaptation(job, frames_info, max(frames))
    px, seed = job.settings, job.config.photons.seed
    calls = []
    for f in frames:
        info = frames_info[f]
        fh = frame_hash(job.render_hash, info, smoothed[f])
        exr, png = frame_paths(job.out_dir, f)
        if f not in force and frame_is_valid(exr, png, px.width, px.height, fh):
            continue
        calls.append((task_key(f"composite-{fh[:8]}-f{f:05d}", job.store_url, job.out_dir), dict(
            store_url=job.store_url, scene_path=job.scene_path, scene_hash=job.scene_hash, camera=job.camera,
            element_size=job.element_size, frame=f, width=px.width, height=px.height, spp=px.spp,
            seed=seed, max_depth=px.reflection_depth, area_samples=px.area_samples,
            adaptation=smoothed[f], tonemap=px.tonemap, out_dir=job.out_dir,
            metadata=dict(scene=job.scene_path.rsplit("/", 1)[-1], scene_hash=job.scene_hash,
                          camera=job.camera_name, render_hash=job.render_hash, frame_hash=fh,
                          config_hash=job.config.hash, photons=info["photons"],
                          seed=seed, spp=px.spp, resolution=f"{px.width}x{px.height}",
                          adaptation=smoothed[f], frame_adaptation=info["adaptation"]))))
    return calls


def _frames_info(job: Job, upto_index: int) -> dict[int, dict]:
    info: dict[int, dict] = {}
    for i in range(upto_index + 1):
        rec = read_record(job.out_dir, i)
        info.update({int(f): v for f, v in rec.frames.items()})
    return info


def segment_task(job: Job, index: int, force: bool = False) -> dict:
    """Dask task for segment ``index``: decide it (if no earlier task did) and the next one, then
    reconstruct and composite its frames. Returns its record as a dict. ``force`` redoes the
    segment's decisions, maps and frames (``loom render --segment``)."""
    with fanout() as client:
        run = SegmentRun(job, client)
        prev = read_record(job.out_dir, index - 1) if index else None
        start = job.first if prev is None else prev.end + 1
        fmax = job.fmax if prev is None else prev.fmax
        if force:
            old = read_record(job.out_dir, index)
            rec = run.decide(index, start, old.fmax if old is not None else fmax) if job.n_photons is None \
                else run._fixed_record(index)
        else:
            rec = run.record(index, start, fmax)
        if rec.end < job.last and rec.guided:
            run.record(index + 1, rec.end + 1, rec.fmax)  # Steps 1-3 of the next segment (§5.2)
        targets = run.reach_targets(rec)
        t0 = time.perf_counter()
        progress(f"segment {index}: frames {rec.start}-{rec.end}: reconstructing (Steps 4-5) and compositing")
        with _writing(job.out_dir):
            rec.frames, written = run.frames(rec, targets, _frames_info(job, index - 1), force)
        t1 = t0 + run.times["temporal_s"]
        for r in written.values():
            run.add_times({f"composite_{k}": v for k, v in r.items() if k.endswith("_s")},
                          ("composite_load_s", "composite_render_s", "composite_write_s"))
        rec.status = "done"
        rec.times_s.update({"frames_s": time.perf_counter() - t0, "reconstruct_s": t1 - t0,
                            "composite_s": time.perf_counter() - t1, **{k: round(v, 4) for k, v in run.times.items()}})
        rec.io_bytes = dict(run.io_bytes)
        write_record(job.out_dir, rec)
        return {"record": rec.to_dict(), "rays": {str(f): r["rays"] for f, r in written.items()},
                "batches": run.batches_traced,
                "frame_times": {str(f): {k: round(v, 4) for k, v in r.items() if k.endswith("_s")}
                                for f, r in written.items()}}


def segment_done(job: Job, index: int) -> SegmentRecord | None:
    """The record of a segment a rerun may skip: done, current and with every frame valid."""
    rec = read_record(job.out_dir, index)
    if rec is None or rec.status != "done" or rec.decision_hash != job.decision_hash:
        return None
    info = _frames_info(job, index)
    frames = [f for f in range(rec.start, rec.end + 1) if f in set(job.selection)]
    if any(f not in info for f in frames):
        return None
    smoothed = smoothed_adaptation(job, info, rec.end)
    for f in frames:
        exr, png = frame_paths(job.out_dir, f)
        fh = frame_hash(job.render_hash, info[f], smoothed[f])
        if not frame_is_valid(exr, png, job.settings.width, job.settings.height, fh):
            return None
    return rec


def coordinate(job: Job, client: Client | None, *, on_segment: Callable[[SegmentRecord, dict], None] | None = None,
               on_progress: Callable[[str], None] | None = None) -> list:
    """Run the segments in order (client side); ``on_segment(record, result)`` after each, with
    the segment task's result (frames written with their rays, batches traced; empty when the
    segment was done already), and ``on_progress(line)`` for the steps inside a segment task.
    Returns the records."""
    records, index, start = [], 0, job.first
    with _progress_to(client, on_progress):
        return _coordinate(job, client, on_segment, records, index, start)


@contextmanager
def _progress_to(client, on_progress):
    if on_progress is None:
        yield
    elif client is None:
        _local_progress.append(on_progress)
        try:
            yield
        finally:
            _local_progress.remove(on_progress)
    else:
        client.subscribe_topic(PROGRESS_TOPIC, lambda event: on_progress(event[1]))
        try:
            yield
        finally:
            client.unsubscribe_topic(PROGRESS_TOPIC)


def _coordinate(job, client, on_segment, records, index, start) -> list:
    while start <= job.last:
        rec = segment_done(job, index)
        result = {"rays": {}, "batches": 0, "already_done": rec is not None}
        if rec is None or (records and rec.start != start):
            if client is None:
                result = segment_task(job, index)
            else:
                result = wait_result(client, client.submit(
                    segment_task, job, index, key=f"segment-{job.decision_hash[:8]}-{index:03d}-"
                    f"{time.time_ns()}", pure=False))
            rec = SegmentRecord.from_dict(result["record"])
        records.append(rec)
        if on_segment:
            on_segment(rec, result)
        index, start = index + 1, rec.end + 1
    _drop_records_after(job, index - 1)
    return records


def _drop_records_after(job: Job, last_index: int) -> None:
    """Remove records (and their pictures) a previous run left beyond this run's last segment."""
    for path in (Path(job.out_dir) / DIRECTORY).glob("segment-*"):
        index = record_index(path)
        if index is not None and index > last_index:
            path.unlink(missing_ok=True)


def reprocess(job: Job, client: Client | None, index: int) -> tuple[SegmentRecord, dict]:
    """Redo segment ``index`` (its frame range kept) and exactly the frames that depend on it: its
    own, the neighbours' whose windows reach into it, and any later frame whose smoothed exposure
    changed; every other frame's files stay untouched."""
    old = read_record(job.out_dir, index)
    if old is None:
        raise LoomError(f"segment {index} has no record yet; render first", field="--segment")
    if client is None:
        result = segment_task(job, index, True)
    else:
        result = wait_result(client, client.submit(
            segment_task, job, index, True, pure=False,
            key=f"segment-{job.decision_hash[:8]}-{index:03d}-redo-{time.time_ns()}"))
    rec = SegmentRecord.from_dict(result["record"])
    rays = {int(f): r for f, r in result["rays"].items()}
    # Neighbours: their windows reach into this segment; recompute their maps, redo changed frames
    run = SegmentRun(job, client)
    for i in (index - 1, index + 1):
        nb = read_record(job.out_dir, i)
        if nb is None or nb.status != "done":
            continue
        nb.frames = run.reconstruct(nb, run.reach_targets(nb))
        write_record(job.out_dir, nb)
    last_index = index
    while read_record(job.out_dir, last_index + 1) is not None:
        last_index += 1
    info = _frames_info(job, last_index)
    later = [f for f in job.selection if f in info]
    rays.update({f: r["rays"] for f, r in composite_frames(job, client, later, info).items()})
    return rec, {"rays": {str(f): r for f, r in sorted(rays.items())}, "batches": result["batches"]}

