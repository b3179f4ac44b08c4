"""``loom render``: check the inputs, then hand the frames to the segment coordinator on Dask.

Here, on the client: every option and the scene are checked before anything is written
(one-line LoomErrors), the photon store and illumination arrays are created (only the client
creates arrays: zarr 3 has no locks), the hashes are computed, and then
pipeline/run/coordinator.py runs one task per segment (§5.2): photons, Steps 1-5, composites.
Afterwards ``preview.mp4`` and ``report.json``.

Hashes. ``render_hash`` covers what pixels depend on besides their maps (scene, camera, seed,
photon settings, resolution, spp, reflection depth, tone mapping); a frame's files carry a
*frame hash* of it, its indirect map's digest and its time-adapted adaptation, and are skipped on a
rerun when that matches. ``decision_hash`` adds what the segment decisions read (the collection,
filter and segment stages of RenderConfig, the frame range, --fmax, --photons): changing d_thr
re-decides the segments and reuses every stored photon.
"""
from __future__ import annotations

import json
import logging
import os
import re
import shutil
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pipeline.collection.maps import check_window_options
from pipeline.config import RenderConfig, stable_digest
from pipeline.errors import LoomError
from pipeline.frames.camera_paths import RAY_KINDS
from pipeline.frames.images import frame_paths, write_video
from pipeline.frames.perceived import viewing_line
from pipeline.frames.settings import MAX_SIDE, RenderSettings
from pipeline.frames.tonemap import LOOK_FIELDS
from pipeline.paths import check_writable_dir
from pipeline.report.page import page_parts, write_report
from pipeline.report.skipped import skipped_work, summary_lines
from pipeline.scene import read_scene
from pipeline.scene.environment import load_environment
from pipeline.scene.scene_cache import keep_scene
from pipeline.segments.job import Job
from pipeline.segments.records import read_records
from pipeline.store import PhotonStore, disk_usage, remove_partials
from pipeline.store.illumination import IlluminationMaps

from .cluster import connect
from .coordinator import coordinate, reprocess
from .shoot import check_store_location, open_store, plan

if TYPE_CHECKING:
    from collections.abc import Callable

    from pipeline.scene import Scene
    from pipeline.segments.records import SegmentRecord

log = logging.getLogger(__name__)
def parse_resolution(text: str) -> tuple[int, int]:
    """``"640x480"`` -> (640, 480); anything else, or a zero side, is a one-line LoomError."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", str(text))
    if not m:
        raise LoomError(f"{text!r} is not WIDTHxHEIGHT, e.g. 640x480", field="--resolution")
    w, h = int(m[1]), int(m[2])
    if not (0 < w <= MAX_SIDE and 0 < h <= MAX_SIDE):
        raise LoomError(f"{text!r}: width and height must be in [1, {MAX_SIDE}]", field="--resolution")
    return w, h


def check_out_dir(out: Path) -> None:
    """Refuse an output location that is a file or cannot be written, before any work."""
    check_writable_dir(out, field="--out")


@dataclass(frozen=True, kw_only=True)
class RenderRequest:
    """What a render is asked to make, as ``loom render`` and ``loom plan`` take it (their job
    options), before :func:`prepare_job` checks it and resolves it into the Job."""

    scene_path: str | Path
    frames: str | None = None  # a frame list (pipeline/scene/timeline.py); None: every frame
    out_dir: str | Path
    settings: RenderSettings = RenderSettings()
    config: RenderConfig = RenderConfig()
    n_photons: int | None = None  # None: guided (--photons auto); else N_frame of every frame
    fmax: int | None = None  # the first segment's F_max, or every frame's when fixed (None: fmax_initial)
    temporal: str = "adaptive"  # adaptive | fixed | off (fixed settings only)
    store_url: str | None = None  # None: OUT/photons.zarr
    camera: str | None = None  # None: the file's first camera
    light: str = "auto"  # none: refuse a file without light instead of lighting it by default
    animation: str | None = None  # the animation that plays first (None: the file's first, pipeline/scene/loader.py)
    variant: str | None = None  # the material variant (None: the primitives' own, pipeline/scene/variants.py)
    environment: tuple[str, float, float] | None = None  # an environment map's file, strength, rotation
    keep_records: bool = False  # also store every photon hit (a render reads only the counts and sums)


def prepare_job(request: RenderRequest) -> Job:
    """Check every input of ``request`` (one-line LoomErrors, before anything is written), then
    create the output folder, the photon store (with the raw hit records if ``keep_records``) and
    its illumination arrays (only the client creates arrays: zarr 3 has no locks) and return the
    coordinator's Job (pipeline/run/coordinator.py)."""
    config, settings = request.config, request.settings
    n_photons, temporal, frames = request.n_photons, request.temporal, request.frames
    out = Path(request.out_dir)
    check_out_dir(out)
    env = None if request.environment is None else load_environment(*request.environment)
    scene = read_scene(request.scene_path, camera=request.camera, light=request.light, animation=request.animation,
                       variant=request.variant, environment=env)
    p = plan(scene, frames, n_photons if n_photons is not None else 1, config.photons)
    store_url = request.store_url or str(out / "photons.zarr")
    check_store_location(store_url)
    cam_name = scene.camera_name  # a node's, or "auto" (pipeline/scene/default_camera.py)
    fmax = config.segments.fmax_initial if request.fmax is None else request.fmax
    check_window_options(temporal, fmax)
    guided = n_photons is None
    if guided:
        if fmax > config.segments.fmax_cap:
            raise LoomError(f"the first segment's F_max {fmax} exceeds fmax_cap {config.segments.fmax_cap}",
                            field="--fmax")
        if p.frames != list(range(p.frames[0], p.frames[-1] + 1)):
            raise LoomError("--photons auto renders a contiguous range of frames (segments are ranges), "
                            f"got {frames!r}", field="--frames")
        if temporal != "adaptive":
            raise LoomError("--photons auto collects photons adaptively (§5.2); use --photons N for "
                            f"--temporal {temporal}", field="--temporal")

    _create_outputs(out, store_url, p, request.keep_records)
    photon_hash = config.photons.photon_hash(p.elements.element_size)
    look = dict(scene_hash=scene.scene_hash, camera=cam_name, seed=config.photons.seed, photon_hash=photon_hash,
                width=settings.width, height=settings.height, spp=settings.spp,
                reflection_depth=settings.reflection_depth, area_samples=settings.area_samples,
                tonemap=settings.tonemap.to_dict(), **({"shutter": settings.shutter} if settings.shutter else {}))
    # The AQM judges with Ward's operator whatever the look (pipeline/frames/tonemap.py): a new look re-decides nothing
    decision = dict(look, tonemap={k: v for k, v in look["tonemap"].items() if k not in LOOK_FIELDS},
                    first=p.frames[0], last=p.frames[-1], fmax=fmax, n_photons=n_photons,
                    temporal=temporal, selection=p.frames, collection=config.collection.hash,
                    filter=config.filter.hash, segments=config.segments.hash)
    decision.pop("shutter", None)  # the AQM judges unblurred frames (pipeline/frames/shutter.py)
    if not guided:  # fixed settings read no segment parameter
        decision.pop("segments")
    # Absolute paths: tasks and farm recipes run elsewhere, and in other working directories
    if "://" not in store_url:
        store_url = str(Path(store_url).resolve())
    keep_scene(str(scene.path.resolve()), request.camera, scene)  # for finish(), and tasks run in this process
    return Job(scene_path=str(scene.path.resolve()), scene_hash=scene.scene_hash, camera=request.camera,
               camera_name=cam_name, element_size=p.elements.element_size, store_url=store_url,
               out_dir=str(out.resolve()),
               first=p.frames[0], last=p.frames[-1], selection=tuple(p.frames), settings=settings, config=config,
               render_hash=stable_digest(look), decision_hash=stable_digest(decision), fmax=fmax,
               n_photons=n_photons, temporal=temporal,
               single_state=len(set(p.sources[f] for f in p.frames)) == 1 and guided,
               animation=scene.animation_option, variant=scene.variant_option,
               environment=None if env is None else env.source)


def _create_outputs(out: Path, store_url: str, p, keep_records: bool) -> None:
    """The output folder, the photon store and its illumination arrays; an OSError (``--out`` under
    /proc, a full disk) is a one-line LoomError, and what this call made is removed again."""
    local_store = "://" not in store_url or store_url.startswith("file://")
    store_path = Path(store_url.removeprefix("file://"))
    made = [path for path in (out, store_path if local_store else None) if path is not None and not path.exists()]
    try:
        out.mkdir(parents=True, exist_ok=True)
        open_store(p, store_url, keep_records=keep_records)
        IlluminationMaps.create(store_url, n_frames=p.scene.timeline.frames, n_vertices=p.elements.n_vertices)
    except OSError as err:
        for path in reversed(made):
            shutil.rmtree(path, ignore_errors=True)
        raise LoomError(f"cannot create the output: {err.strerror or err}", path=str(out), field="--out") from None


@dataclass
class RenderTally:
    """What the segment tasks of this process reported, for the report: the rays and seconds of each
    frame written, the segments found done already, the photon batches traced."""

    rays: dict[int, dict] = field(default_factory=dict)
    frame_times: dict[int, dict] = field(default_factory=dict)
    segments_done: list[dict] = field(default_factory=list)
    batches: int = 0

    def add(self, rec: SegmentRecord, result: dict) -> None:
        """Count a segment task's ``result`` (pipeline/run/coordinator.py segment_task) for ``rec``."""
        self.rays.update({int(f): r for f, r in result["rays"].items()})
        self.frame_times.update({int(f): t for f, t in result.get("frame_times", {}).items()})
        if result.get("already_done"):
            self.segments_done.append({"index": rec.index, "frames": [rec.start, rec.end]})
        self.batches += result["batches"]


def segment_line(rec: SegmentRecord, result: dict) -> str:
    """The progress line of a finished segment."""
    d = f", d_AQM {rec.d_aqm:.2f} %" if rec.d_aqm is not None else ""
    cap = " (n_frame_max reached)" if rec.capped else ""
    return (f"segment {rec.index}: frames {rec.start}-{rec.end}, K {rec.k}, F_max {rec.fmax_text}, "
            f"N_frame {rec.n_frame:,}{d}{cap}; {len(result['rays'])} frames written")


def render(request: RenderRequest, *, scheduler: str = "local", workers: int | None = None,
           segment: int | None = None, echo: Callable[[str], None] | None = None,
           performance_report: str | None = None) -> dict:
    """Render what ``request`` asks for; returns the report (also ``report.json``).

    ``request.n_photons`` None (``--photons auto``): the segment planner chooses N_frame and F_max
    per segment (pipeline/segments/planner.py, §5.2), ``fmax`` is the first segment's F_max. An
    integer keeps them fixed for every frame (``--photons N --fmax F``), with ``temporal`` adaptive,
    fixed or off. ``scheduler`` and ``workers`` as pipeline/run/cluster.py connect takes them.
    ``segment`` redoes one segment and the frames that depend on it. ``echo`` gets progress lines
    (and the Dask dashboard link); ``performance_report`` an HTML file for Dask's report.
    """
    if segment is not None and segment < 0:
        raise LoomError(f"must be a segment index >= 0, got {segment}", field="--segment")
    t_start = time.perf_counter()
    tally = RenderTally()

    def on_segment(rec: SegmentRecord, result: dict) -> None:
        tally.add(rec, result)
        if echo is not None:
            echo(segment_line(rec, result))

    # The scheduler is reached before anything is written: an address with nothing listening
    # leaves no output folder behind. The report, video and figures (finish) are made while the
    # cluster closes: both are serial ends of the run (docs/13-cluster.md §4).
    with ThreadPoolExecutor(1) as pool:
        with connect(scheduler, workers, performance_report=performance_report, echo=echo) as client:
            job = prepare_job(request)
            if echo is not None:
                echo(_viewing(job))
            if segment is not None:
                on_segment(*reprocess(job, client, segment))
                records = read_records(job.out_dir)
            else:
                records = coordinate(job, client, on_segment=on_segment,
                                     on_progress=None if echo is None else (lambda line: echo(f"  {line}")))
            _import_for_finish()
            finishing = pool.submit(finish, job, records, tally, t_start)
        report = finishing.result()
    if echo is not None:
        for line in summary_lines(report["skipped_work"]):
            echo(f"skipped: {line}")
    return report


def _import_for_finish() -> None:
    """Import, in this thread, the heavy modules :func:`finish` imports when it first draws.

    finish runs in a thread while the cluster closes, and a closing Dask server removes its work
    directory from ``sys.path``: an import walking ``sys.path`` in another thread at that moment can
    skip the entry after it, site-packages, and fail with ModuleNotFoundError (seen as "No module
    named 'matplotlib'" or 'PIL' at the end of a cluster render). Imported first, they are found in
    ``sys.modules``, and their submodules are looked up in the packages' own paths."""
    import imageio_ffmpeg  # noqa: F401  the preview video (pipeline/frames/images.py)
    import matplotlib.backends.backend_agg  # noqa: F401  the report's figures (pipeline/report/figures.py)
    import matplotlib.figure  # noqa: F401
    import matplotlib.ticker  # noqa: F401
    import PIL.Image  # noqa: F401  the report's filmstrip (pipeline/report/page.py)


def _timed(func: Callable, *args) -> float:
    """Seconds ``func(*args)`` took."""
    t0 = time.perf_counter()
    func(*args)
    return time.perf_counter() - t0


def finish(job: Job, records: list[SegmentRecord], tally: RenderTally | None, t_start: float) -> dict:
    """The segment figure, ``preview.mp4``, ``report.json`` and ``report.html`` (pipeline/report/page.py)
    of a rendered job, timed from ``t_start``. ``tally`` None: the frames were written by other
    processes (a farm's recipes), whose ray counts and timings this one does not know."""
    out = Path(job.out_dir)
    rays = {} if tally is None else tally.rays
    frame_times = {} if tally is None else tally.frame_times
    video = out / "preview.mp4"
    scene = job.scene_ref.scene()
    report = {
        "scene": job.scene_path, "camera": job.camera_name, "frames": list(job.selection),
        "animations": {"played": list(scene.animations_played), "left_out": list(scene.animations_left_out)},
        "rendered": sorted(rays), "skipped": sorted(set(job.selection) - set(rays)),
        "resolution": [job.settings.width, job.settings.height], "spp": job.settings.spp,
        "photons": "auto" if job.n_photons is None else job.n_photons,
        "segments": [{"index": r.index, "frames": [r.start, r.end], "k": r.k, "fmax": r.fmax,
                      "windows_fmax": r.windows_fmax, "n_frame": r.n_frame, "d_aqm": r.d_aqm, "capped": r.capped}
                     for r in records],
        "viewing": _viewing(job),
        "store": job.store_url, "store_size": store_size(job.store_url), "video": str(video),
        "render_hash": job.render_hash,
        "photon_batches_traced": 0 if tally is None else tally.batches, "times_s": {},
        "rays": {k: sum(r[k] for r in rays.values()) for k in RAY_KINDS},
        "rays_per_frame": {str(f): rays[f] for f in sorted(rays)},
        "frame_times_s": {str(f): frame_times[f] for f in sorted(frame_times)},
        "skipped_work": _skipped(job, scene, tally, records),
        "settings": _settings(job),
    }
    # The video (an ffmpeg process) encodes while this process draws the report's figures: both
    # are the render's last serial steps (docs/13-cluster.md §4)
    with ThreadPoolExecutor(1) as pool:
        encoding = pool.submit(_timed, write_video, [frame_paths(out, f)[1] for f in job.selection], video,
                               scene.timeline.fps)
        try:
            parts = page_parts(out, report, records)
        finally:
            video_s = encoding.result()
    times = {k: round(sum(r.times_s.get(k, 0.0) for r in records), 3)
             for k in ("shoot_s", "aqm_s", "temporal_s", "reconstruct_s", "composite_s", "decide_s")}
    times.update(video_s=round(video_s, 3), total_s=round(time.perf_counter() - t_start, 3))
    report["times_s"] = times
    tmp = out / f".report.json.{os.getpid()}.partial"
    tmp.write_text(json.dumps(report, indent=1))
    os.replace(tmp, out / "report.json")
    write_report(out, parts)
    _remove_leftovers(out, job.store_url)
    return report


def _viewing(job: Job) -> str:
    """The viewing conditions the AQM judged the frames under, with their pixels per degree."""
    px = job.settings
    return viewing_line(px.tonemap, px.width, px.height, job.config.segments.aqm_size)


def _settings(job: Job) -> dict:
    """The report's settings: the job's values, its frame settings among them, and its RenderConfig."""
    plain = job.to_dict()
    rest = {k: v for k, v in plain.items() if k not in ("config", "selection", "settings")}
    return {"job": {**rest, **plain["settings"]}, "config": plain["config"]}


def store_size(store_url: str) -> dict:
    """The photon store's bytes on disk by part (pipeline/store disk_usage; None for a remote
    store), the photons its batches hold and the bytes a photon costs: the render's last lines and
    the report say them."""
    store = PhotonStore.open(store_url)
    traced = np.unique(store.source_frames())
    photons = int(store.emitted()[traced].sum())
    parts = disk_usage(store_url)
    return {"photons": photons, "keep_records": store.keep_records, "bytes": parts,
            "bytes_per_photon": None if parts is None or not photons else
            (parts["photons"] + parts["records"]) / photons}


def _skipped(job: Job, scene: Scene, tally: RenderTally | None, records: list[SegmentRecord]) -> dict:
    """pipeline/report/skipped.py's account of the frames of ``job``, from the store's sharing table
    and the segment records."""
    store = PhotonStore.open(job.store_url)
    sources = {f: store.source_frame(f - 1) + 1 for f in job.selection}
    return skipped_work(job.selection, sources=sources, has_specular=scene.has_specular,
                        has_area_lights=scene.has_area_lights, rays=None if tally is None else tally.rays,
                        segments_done=[] if tally is None else tally.segments_done, has_sky=scene.sky is not None,
                        segments_unlit=[{"index": r.index, "frames": [r.start, r.end], "n_frame": r.n_frame}
                                        for r in records if r.without_indirect_light])


def _remove_leftovers(out: Path, store_url: str) -> None:
    """Temporary files killed writers left (``.NAME.PID[.ID].partial``, zarr's ``zarr.UUID.partial``)
    in the output folder and a local photon store: with every frame done, no writer of this run is
    alive that could still rename one into place (zarr never reads them either way)."""
    for tmp in [*out.glob(".*.partial*"), *out.glob("segments/.*.partial*"), *out.glob(".farm/.*.partial*")]:
        tmp.unlink(missing_ok=True)
    remove_partials(store_url)
