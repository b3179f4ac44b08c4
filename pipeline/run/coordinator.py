"""The segment coordinator: §5.2 for one animation segment at a time, as a Dask task.

``coordinate`` (in the client) runs one :func:`segment_task` per segment, in segment order as the
paper does: segment i+1 starts after segment i's end with its F_max. Each segment task fans out
its own photon batches, reconstruction and frame tasks from inside the task through distributed's
``worker_client`` (which secedes from the worker's thread pool, so even one one-thread worker
cannot deadlock); with ``--scheduler synchronous`` the same code runs them in-process. Task i:

1. Steps 1-3 for segment i if no task decided it yet (i = 0, or a stale record), then for segment
   i + 1, whose photons segment i's windows reach (§5.2: "Steps 1-3 are performed not only for the
   current segment but for the subsequent segment as well"); the previous segment's photons are
   in the store already. The planner decides (pipeline/segments/planner.py: the pilot, the F_max
   and N_frame loops, the end frames' photons, the record); :class:`DaskExecutor` traces the
   photon batches it asks for as tasks.
2. Steps 4-5 (§5.2.4-5) for the frames of segment i: reconstruction tasks of ``CHUNK_FRAMES``
   frames each (workers/reconstruct.reconstruct_task), then one composite task a frame.

Records (pipeline/segments/records.py) are written when a segment is decided and when it is done;
a rerun skips done segments whose frames are valid and reuses every stored photon batch. Which
photons a frame uses is fixed by the records (the fewest leading batches holding its target),
never by what else the store holds, so results do not depend on the order work happened in, on
the worker count or on a resume.
"""
from __future__ import annotations

import time
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterable, Iterator, Sequence

from distributed import get_worker, worker_client

from pipeline.collection.maps import WindowSpec
from pipeline.config import stable_digest
from pipeline.errors import LoomError
from pipeline.frames.images import frame_is_valid, frame_paths
from pipeline.frames.tonemap import adapt_in_time
from pipeline.photons.tracing import PhotonRange
from pipeline.segments.job import Job
from pipeline.segments.planner import SegmentPlanner, batches_in_use, next_batches, reach_targets
from pipeline.segments.records import DIRECTORY, SegmentRecord, read_record, record_index, write_record
from pipeline.store import PhotonStore
from workers.composite import CompositeRequest, composite_task
from workers.reconstruct import ReconstructRequest, reconstruct_task
from workers.shoot import ShootRequest, shoot_task

from .cluster import TASK_RETRIES, completed, group_sizes, run_tasks, submit_grouped, task_key
from .cluster import result as wait_result
from .shoot import shoot_key, store_identity

if TYPE_CHECKING:
    from distributed import Client

CHUNK_FRAMES = 16  # frames per reconstruction task: fixed, so the gather's bits never depend on workers
# Frames per photon-batch task and per composite task at most (pipeline/run/cluster.py group_sizes,
# whose groups shrink to single frames at the end of a run): ROOM's batches take about 0.06 s and
# its composites 0.17 s a frame, against 8 ms of Dask's own CPU a task.
SHOOT_GROUP, COMPOSITE_GROUP = 8, 4


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


class DaskExecutor:
    """A segment task's executor (pipeline/segments/planner.py ``Executor``): photon batches as Dask
    tasks, Steps 4-5 and the composites fanned out; the store, and the seconds and bytes its tasks
    report. Without a client (``--scheduler synchronous``, the farm's steps) the tasks run here."""

    def __init__(self, job: Job, client: Client | None):
        self.job, self.client = job, client
        self.config = job.config
        # A store swapped for another run's (another scene, photon settings or seed) is refused here
        self.store = PhotonStore.open(job.store_url, mode="r+",
                                      identity=store_identity(job.scene_hash, job.element_size, self.config.photons))
        self.times = {"shoot_s": 0.0, "aqm_s": 0.0, "temporal_s": 0.0}
        self.io_bytes: dict[str, int] = {}  # what the tasks read and wrote (store.counting_io)
        self.batches_traced = 0

    def planner(self) -> SegmentPlanner:
        """The planner of the job's segments, asking this executor for its photons."""
        return SegmentPlanner(self.job, self.store, self, self.times)

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

    def progress(self, message: str) -> None:
        """The planner's line, as a worker event or to the local callbacks (:func:`progress`)."""
        progress(message)

    # --- photons ---------------------------------------------------------------------------
    def shoot(self, targets: dict[int, int]) -> None:
        """Trace one batch more for every frame whose stored batches hold fewer than its target."""
        t0 = time.perf_counter()
        job = self.job
        calls = [(shoot_key(self.config.photons, job.element_size, b.frame, b.batch, job.store_url),
                  ShootRequest(job.scene_ref, job.store_url, b.batch, PhotonRange(b.frame, b.photon_start, b.n_photons),
                               self.config.photons))
                 for b in next_batches(self.store, targets)]
        with _writing(job.store_url):
            results = run_tasks(self.client, shoot_task, calls, desc="shoot", progress=False,
                                group=group_sizes(len(calls), len(self.workers()), SHOOT_GROUP))
        for r in results.values():
            self.add_times(r, ("pose_s", "trace_s", "write_s", "sums_s", "shoot_read_bytes", "shoot_write_bytes"))
        self.batches_traced += len(calls)
        self.times["shoot_s"] += time.perf_counter() - t0

    # --- Steps 4-5 and the frames --------------------------------------------------------------
    def frames_of(self, rec: SegmentRecord) -> list[int]:
        sel = set(self.job.selection)
        return [f for f in range(rec.start, rec.end + 1) if f in sel]

    def reconstruct_calls(self, rec: SegmentRecord, targets: dict[int, int]) -> list[tuple[str, ReconstructRequest]]:
        """One reconstruction task per chunk of :func:`frame_chunks` of the segment's frames."""
        job = self.job
        use = tuple(batches_in_use(self.store, targets).tolist())
        windows = WindowSpec(rec.temporal, rec.windows_fmax)
        return [(task_key(f"reconstruct-{job.decision_hash[:8]}-f{chunk[0]:05d}", job.store_url),
                 ReconstructRequest(job.scene_ref, job.store_url, tuple(chunk), windows, use, job.config, job.settings))
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

        def take(result: dict, chunk_frames: tuple[int, ...]) -> list[tuple[str, CompositeRequest]]:
            self._took(result)
            out.update(result["frames"])
            info.update({int(f): v for f, v in result["frames"].items()})
            return composite_calls(self.job, chunk_frames, info, force=forced)

        if self.client is None:
            for _, request in calls:
                for _, composite in take(reconstruct_task(request), request.frames):
                    r = composite_task(composite)
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
        chunk_of = {submit(reconstruct_task, request, key=key, retries=TASK_RETRIES, pure=False,
                           priority=len(calls) - i,
                           workers=[workers[i * len(workers) // len(calls)]] if workers else None,
                           allow_other_workers=True): i
                    for i, (key, request) in enumerate(calls)}
        ready, following, composites = {}, 0, {}
        for future, result in completed(self.client, list(chunk_of)):
            ready[chunk_of[future]] = result
            while following in ready:
                todo = take(ready.pop(following), calls[following][1].frames)
                left = sum(len(request.frames) for _, request in calls[following:])  # the segment's frames from here
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


def frame_hash(render_hash: str, info: dict, adaptation: float) -> str:
    """What a frame's files depend on: the render's settings, its indirect map and its exposure."""
    return stable_digest({"render": render_hash, "map": info["digest"], "adaptation": float(adaptation)})


def smoothed_adaptation(job: Job, frames_info: dict[int, dict], upto: int) -> dict[int, float]:
    """The eye's adaptation L_a of each rendered frame up to ``upto``: the time course of
    pipeline/frames/tonemap.py (adapt_in_time) over the frames' own L_wa in the records, at the timeline's
    times. It is causal, so a segment's frames need only the L_wa of the frames before them."""
    scene = job.scene_ref.scene()
    frames = [f for f in job.selection if f <= upto]
    values = adapt_in_time([frames_info[f]["adaptation"] for f in frames],
                           [scene.timeline.time(f) for f in frames], job.settings.tonemap)
    return dict(zip(frames, values.tolist()))


def composite_frames(job: Job, client: Client | None, frames: Sequence[int], frames_info: dict[int, dict], *,
                     force: frozenset = frozenset()) -> dict[int, dict]:
    """Composite every frame of ``frames`` whose files do not carry its current frame hash (and
    those in ``force``); returns the composite task's result (rays per kind, timings) of every frame
    written."""
    done = run_tasks(client, composite_task, composite_calls(job, frames, frames_info, force=force),
                     desc="composite", progress=False)
    return {int(r["frame"]): r for r in done.values()}


def composite_calls(job: Job, frames: Sequence[int], frames_info: dict[int, dict], *,
                    force: frozenset = frozenset()) -> list[tuple[str, CompositeRequest]]:
    """(key, request) of the composite tasks of the frames in ``frames`` that need one (see
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
        metadata = dict(scene=job.scene_path.rsplit("/", 1)[-1], scene_hash=job.scene_hash,
                        camera=job.camera_name, render_hash=job.render_hash, frame_hash=fh,
                        config_hash=job.config.hash, photons=info["photons"],
                        seed=seed, spp=px.spp, resolution=f"{px.width}x{px.height}",
                        adaptation=smoothed[f], frame_adaptation=info["adaptation"])
        calls.append((task_key(f"composite-{fh[:8]}-f{f:05d}", job.store_url, job.out_dir),
                      CompositeRequest(job.scene_ref, job.store_url, f, px, seed, smoothed[f], job.out_dir, metadata)))
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
        run = DaskExecutor(job, client)
        planner = run.planner()
        prev = read_record(job.out_dir, index - 1) if index else None
        start = job.first if prev is None else prev.end + 1
        fmax = job.fmax if prev is None else prev.fmax
        if force:
            old = read_record(job.out_dir, index)
            rec = planner.decide(index, start, old.fmax if old is not None else fmax)
        else:
            rec = planner.record(index, start, fmax)
        if rec.end < job.last and rec.guided:
            planner.record(index + 1, rec.end + 1, rec.fmax)  # Steps 1-3 of the next segment (§5.2)
        targets = reach_targets(job, rec)
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
    run = DaskExecutor(job, client)
    for i in (index - 1, index + 1):
        nb = read_record(job.out_dir, i)
        if nb is None or nb.status != "done":
            continue
        nb.frames = run.reconstruct(nb, reach_targets(job, nb))
        write_record(job.out_dir, nb)
    last_index = index
    while read_record(job.out_dir, last_index + 1) is not None:
        last_index += 1
    info = _frames_info(job, last_index)
    later = [f for f in job.selection if f in info]
    rays.update({f: r["rays"] for f, r in composite_frames(job, client, later, info).items()})
    return rec, {"rays": {str(f): r for f, r in sorted(rays.items())}, "batches": result["batches"]}

