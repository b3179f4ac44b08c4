"""``loom render``: shoot, illuminate and composite a scene's frames end to end on Dask.

Stages, all on one Dask client (DESIGN.md data flow):

1. shoot       (frame, batch) photon tasks into ``DIR/photons.zarr`` (pipeline/shoot.py), resumable;
2. illuminate  per frame: vertex irradiance maps from the frame's own photons into the store and
               the frame's adaptation luminance from its mesh-based lighting (workers/reconstruct.py);
               with ``temporal`` adaptive or fixed, the indirect maps are then replaced by the
               temporal gather (pipeline/temporal.py);
3. adapt       the coordinator smooths adaptation over the frames in time (pipeline/tonemap.py),
               so each composite task gets its own value and exposure never jumps;
4. composite   per frame: ray-traced direct and specular light plus the indirect map, EXR and PNG
               written atomically (workers/composite.py, pipeline/images.py);
5. preview.mp4 from the PNGs and ``report.json``.

A frame whose EXR and PNG exist, decode and carry this render's hash is skipped on a rerun.
Everything the user can get wrong is checked before anything is written (one-line LoomErrors).
"""
from __future__ import annotations

import json
import logging
import os
import re
import time
from dataclasses import dataclass, field
from pathlib import Path

from .cluster import connect, run_tasks
from .config import RenderConfig, stable_digest
from .errors import LoomError
from .images import exr_metadata, frame_is_valid, frame_paths, write_video
from .scene import Scene
from .shoot import check_store_location, open_store, plan
from .shoot import tasks as shoot_tasks
from .tonemap import ToneMapping, smooth_adaptation

log = logging.getLogger(__name__)
MAX_SIDE = 16384
RAY_KINDS = ("camera", "shadow", "area", "reflection")


@dataclass(frozen=True, kw_only=True)
class RenderSettings:
    """What a frame's pixels depend on besides the scene, photons and seed."""

    width: int = 640
    height: int = 480
    spp: int = 4  # jittered camera samples per pixel
    max_depth: int = 4  # mirror/glossy reflections followed per camera path
    area_samples: int = 2  # area-light samples per diffuse hit (scenes with emissive triangles)
    tonemap: ToneMapping = field(default_factory=ToneMapping)

    def __post_init__(self) -> None:
        for name, lo, hi in (("width", 1, MAX_SIDE), ("height", 1, MAX_SIDE), ("spp", 1, 4096),
                             ("max_depth", 0, 64), ("area_samples", 1, 256)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
                flag = "--resolution" if name in ("width", "height") else f"--{name.replace('_', '-')}"
                raise LoomError(f"{name} must be an integer in [{lo}, {hi}], got {value!r}", field=flag)


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
    if out.exists() and not out.is_dir():
        raise LoomError("exists and is not a directory", path=str(out), field="--out")
    parent = out
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK):
        raise LoomError(f"is not writable ({parent} does not allow writing)", path=str(out), field="--out")


def render(scene_path, *, frames: str | None, out_dir, settings: RenderSettings = RenderSettings(),
           n_photons: int = 40_000, store_url: str | None = None, camera: str | None = None,
           config: RenderConfig = RenderConfig(), scheduler: str = "local", workers: int | None = None,
           progress: bool = True, temporal: str = "off", fmax: int | None = None) -> dict:
    """Render ``frames`` of a scene into ``out_dir``; returns the report (also ``report.json``).

    ``temporal`` (adaptive | fixed | off) and ``fmax`` (default ``config.fmax_initial``) choose the
    temporal photon collection of the indirect maps (§5.1, §5.2.4; pipeline/temporal.py).
    """
    from workers.composite import composite_task
    from workers.photons import shoot_task
    from workers.reconstruct import illuminate_task

    from .store.illumination import IlluminationMaps

    # Check every input before anything is written
    out = Path(out_dir)
    check_out_dir(out)
    scene = Scene.load(scene_path, camera=camera)
    if scene.camera_node is None:
        raise LoomError("has no perspective camera to render from", path=str(scene_path), field="cameras")
    p = plan(scene, frames, n_photons, config)
    store_url = store_url or str(out / "photons.zarr")
    check_store_location(store_url)
    cam_name = scene.nodes[scene.camera_node].name
    if temporal not in ("adaptive", "fixed", "off"):
        raise LoomError(f"must be adaptive, fixed or off, got {temporal!r}", field="--temporal")
    fmax = config.fmax_initial if fmax is None else fmax
    if not 0 <= fmax <= 510:
        raise LoomError(f"must be in [0, 510] frames, got {fmax}", field="--fmax")
    t_start = time.perf_counter()

    out.mkdir(parents=True, exist_ok=True)
    store = open_store(p, store_url)
    timing, counts = {}, {}
    with connect(scheduler, workers) as client:
        # 1. Photons
        t0 = time.perf_counter()
        todo = shoot_tasks(p, store, store_url)
        shot = run_tasks(client, shoot_task, todo, desc="shoot", progress=progress)
        timing["shoot_s"] = time.perf_counter() - t0
        counts["photon_rays"] = sum(r.get("rays", 0) for r in shot.values())

        # Which frames are already done (same render hash)
        emitted = {f: store.photons_emitted(f - 1) for f in p.frames}
        base = dict(scene_hash=scene.scene_hash, camera=cam_name, seed=config.seed,
                    photon_hash=config.photon_hash(p.elements.element_size), n_photons=n_photons,
                    width=settings.width, height=settings.height, spp=settings.spp,
                    max_depth=settings.max_depth, area_samples=settings.area_samples,
                    tonemap=settings.tonemap.to_dict())
        if temporal != "off":  # keeps the hash of renders without temporal collection
            base.update(temporal=temporal, fmax=fmax, temporal_config=config.hash)
        render_hash = stable_digest(base)
        done = {}  # frame -> its own (unsmoothed) adaptation luminance, from its EXR
        for f in p.frames:
            exr, png = frame_paths(out, f)
            if frame_is_valid(exr, png, settings.width, settings.height, render_hash):
                own = exr_metadata(exr).get("frame_adaptation")
                if isinstance(own, float) and own > 0:
                    done[f] = own

        # 2. Illumination maps and adaptation (frames already done keep theirs)
        t0 = time.perf_counter()
        IlluminationMaps.create(store_url, n_frames=scene.timeline.frames,
                                n_vertices=p.elements.n_vertices)
        need = [f for f in p.frames if f not in done]
        common = dict(store_url=store_url, scene_path=str(scene.path), scene_hash=scene.scene_hash,
                      camera=camera, element_size=p.elements.element_size)
        lit = run_tasks(client, illuminate_task,
                        [(f"illuminate-{render_hash[:8]}-f{f:05d}", dict(
                            common, frame=f, aspect=settings.width / settings.height)) for f in need],
                        desc="illuminate", progress=progress)
        if temporal != "off" and need:  # indirect maps from temporal windows (pipeline/temporal.py)
            from .temporal import write_temporal_maps
            write_temporal_maps(store_url, scene, p.elements, need, mode=temporal, fmax=fmax, config=config)
        adaptation = dict(done)
        adaptation.update({r["frame"]: r["adaptation"] for r in lit.values()})
        timing["illuminate_s"] = time.perf_counter() - t0

        # 3. Adaptation smoothed over the frames in time
        smoothed = smooth_adaptation([adaptation[f] for f in p.frames],
                                     [scene.timeline.time(f) for f in p.frames], settings.tonemap.tau)
        smoothed = dict(zip(p.frames, smoothed.tolist()))

        # 4. Composite
        t0 = time.perf_counter()
        meta = dict(scene=scene.path.name, scene_hash=scene.scene_hash, camera=cam_name,
                    config_hash=config.hash, render_hash=render_hash, seed=config.seed,
                    spp=settings.spp, resolution=f"{settings.width}x{settings.height}")
        calls = [(f"composite-{render_hash[:8]}-f{f:05d}", dict(
            common, frame=f, width=settings.width, height=settings.height, spp=settings.spp,
            seed=config.seed, max_depth=settings.max_depth, area_samples=settings.area_samples,
            adaptation=smoothed[f], tonemap=settings.tonemap.to_dict(), out_dir=str(out),
            metadata=dict(meta, photons=emitted[f], adaptation=smoothed[f],
                          frame_adaptation=adaptation[f])))
            for f in p.frames if f not in done]
        composited = run_tasks(client, composite_task, calls, desc="composite", progress=progress)
        timing["composite_s"] = time.perf_counter() - t0

    # 5. Video and report
    t0 = time.perf_counter()
    video = out / "preview.mp4"
    write_video([frame_paths(out, f)[1] for f in p.frames], video, scene.timeline.fps)
    timing["video_s"] = time.perf_counter() - t0
    timing["total_s"] = time.perf_counter() - t_start

    per_frame = {r["frame"]: r["rays"] for r in composited.values()}
    for f in sorted(per_frame):
        log.info("frame %d rays: %s", f, ", ".join(f"{k} {v}" for k, v in per_frame[f].items()))
    rays = {k: sum(r[k] for r in per_frame.values()) for k in RAY_KINDS}
    report = {
        "scene": str(scene.path), "camera": cam_name, "frames": p.frames,
        "rendered": sorted(per_frame), "skipped": sorted(done),
        "resolution": [settings.width, settings.height], "spp": settings.spp,
        "photons_per_frame": n_photons, "photon_batches_traced": len(todo),
        "store": store_url, "video": str(video), "render_hash": render_hash,
        "times_s": {k: round(v, 3) for k, v in timing.items()},
        "rays": {**rays, "photon": counts["photon_rays"]},
        "rays_per_frame": {str(f): per_frame[f] for f in sorted(per_frame)},
        "adaptation": {str(f): smoothed[f] for f in p.frames},
    }
    tmp = out / f".report.json.{os.getpid()}.partial"
    tmp.write_text(json.dumps(report, indent=1))
    os.replace(tmp, out / "report.json")
    return report
