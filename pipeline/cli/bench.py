"""``loom bench ...``: the benchmarks' options; what they measure lives in pipeline/benchmarks/."""
from __future__ import annotations

import click

from .render import RENDER_SPP

_RENDER_SPP_HELP = "Camera samples per pixel of every run (default: loom render's, RenderSettings.spp)."

@click.group("bench")
def bench() -> None:
    """Benchmarks (speed is measured here, never in tests)."""


@bench.command("photons")
@click.argument("scenes", nargs=-1)
@click.option("--photons", type=int, default=200_000, show_default=True, help="Photons per worker.")
@click.option("--workers", type=int, default=None, help="Worker processes (default: one per core).")
@click.option("--memory-photons", type=int, default=1_000_000, show_default=True,
              help="Photons of the frame whose peak memory is measured.")
def bench_photons(scenes, photons, workers, memory_photons) -> None:
    """Photon tracing throughput vs raw Embree (default scenes: room atrium)."""
    import os

    from pipeline.benchmarks.photons import run

    run(list(scenes) or ["room", "atrium"], photons=photons, workers=workers or os.cpu_count() or 1,
        memory_photons=memory_photons, echo=click.echo)


@bench.command("aqm")
@click.option("--repeat", type=click.IntRange(1, 1000), default=10, show_default=True,
              help="Timed runs per variant (after one cold run).")
def bench_aqm(repeat):
    """Seconds per 256x256 frame pair of the AQM, without and with pixel flow (NumPy, one core)."""
    from pipeline.benchmarks.aqm import run

    run(repeat, echo=click.echo)


@bench.command("frame")
@click.argument("scenes", nargs=-1)
@click.option("--resolution", default="640x480", show_default=True)
@click.option("--spp", type=int, default=1, show_default=True)
@click.option("--repeat", type=int, default=5, show_default=True, help="Timed renders per scene (median).")
def bench_frame(scenes, resolution, spp, repeat):
    """Milliseconds per frame and rays/s vs raw embreex (default scenes: ROOM and ATRIUM)."""
    from pipeline.benchmarks.frame import run
    from pipeline.frames.settings import RenderSettings
    from pipeline.run.render import parse_resolution

    width, height = parse_resolution(resolution)
    RenderSettings(width=width, height=height, spp=spp)  # validates spp
    run(scenes, width=width, height=height, spp=spp, repeat=repeat, echo=click.echo)


@bench.command("temporal")
@click.option("--trace-frames", type=int, default=3, show_default=True,
              help="Real ATRIUM frames shot to measure tracing time per frame.")
@click.option("--numpy-frames", type=int, default=4, show_default=True, help="Frames for the NumPy twins.")
@click.option("--frames", "n_frames", type=click.IntRange(1), default=None,
              help="Synthetic frames gathered (default: the benchmark's 300; a few for a quick check).")
def bench_temporal(trace_frames: int, numpy_frames: int, n_frames: int) -> None:
    """Temporal windows, gather and filter on PoCL, ATRIUM-size (about 43,000 elements, 300 frames,
    20,000 photons per frame, F_max = 44), against the photon tracing time per frame."""
    from pipeline.benchmarks.temporal import run

    run(trace_frames, numpy_frames, **({} if n_frames is None else {"n_frames": n_frames}))


@bench.command("noise")
@click.option("--photons", default="10000,20000,40000,80000", show_default=True,
              help="N_frame values, comma-separated (shot incrementally into one store).")
@click.option("--fmax", type=int, default=30, show_default=True, help="F_max, frames of the segment around K = 68.")
@click.option("--resolution", default="320x240", show_default=True, help="Frame size of I1, I2.")
@click.option("--spp", type=int, default=2, show_default=True)
@click.option("--element-scale", type=float, default=1.0, show_default=True,
              help="Element size as a multiple of the scene's own (0.4 m for ROOM).")
@click.option("--filter-photons", type=float, default=None,
              help="filter_photons of the filtered column (default: RenderConfig's).")
@click.option("--calibrate/--no-calibrate", default=True, show_default=True,
              help="Also find the per-vertex noise amplitude the AQM puts at d_thr.")
@click.option("--scheduler", default="synchronous", show_default=True, help="synchronous, local or an address.")
@click.option("--workers", type=int, default=None, help="Workers of a local scheduler.")
@click.option("--store", default=None, help="Directory to keep the scene and photons in (default: a temporary one).")
def bench_noise(photons, fmax, resolution, spp, element_scale, filter_photons, calibrate, scheduler, workers, store):
    """d_AQM of the even/odd renderings I1(K), I2(K) of ROOM frame 68 against N_frame: linear vs
    displayed input, spatial filter, window statistics, and the AQM's noise threshold."""
    from pipeline.benchmarks.noise import run
    from pipeline.run.render import parse_resolution

    width, height = parse_resolution(resolution)
    run(tuple(int(p) for p in photons.split(",") if p.strip()), fmax=fmax, width=width, height=height, spp=spp,
        element_scale=element_scale, filter_photons=filter_photons, calibrate=calibrate, scheduler=scheduler,
        workers=workers, store=store)


@bench.command("render")
@click.argument("scene", default="room")
@click.option("--frames", default=None, help="Frame range (default: all of the scene's frames).")
@click.option("--resolution", default="320x240", show_default=True)
@click.option("--spp", type=int, default=RENDER_SPP, show_default=True, help=_RENDER_SPP_HELP)
@click.option("--workers", type=int, default=2, show_default=True, help="Workers of the guided and the scaled run.")
@click.option("--photons", "n_photons", type=int, default=40_000, show_default=True, help="Fixed N_frame.")
@click.option("--fmax", type=int, default=30, show_default=True, help="Fixed F_max.")
@click.option("--skip-guided", is_flag=True, help="Only the fixed runs (Table 2 b and scaling).")
@click.option("--repeat", type=click.IntRange(1, 20), default=1, show_default=True,
              help="Pairs of fixed runs (1 worker and --workers, in ABBA order); the scaling is their median.")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None, help="Also write the figures here.")
def bench_render(scene, frames, resolution, spp, workers, n_photons, fmax, skip_guided, repeat, json_path):
    """Table 2 per frame (guided and fixed N_frame/F_max) and 1 vs N worker scaling (default: ROOM)."""
    from pipeline.benchmarks.render import run
    from pipeline.run.render import parse_resolution

    width, height = parse_resolution(resolution)
    run(scene, frames=frames, width=width, height=height, spp=spp, workers=workers, n_photons=n_photons, fmax=fmax,
        skip_guided=skip_guided, repeat=repeat, json_path=json_path, echo=click.echo)


@bench.command("error")
@click.argument("scene", default="room")
@click.option("--quick", is_flag=True,
              help="Small budgets and frame range (a few minutes for room once its references are traced).")
@click.option("--frames", default=None, help="FIRST-LAST (default: the plan's, e.g. 46-90 for room).")
@click.option("--budgets", default=None, help="N_frame values, comma-separated (default: the plan's).")
@click.option("--fmax", type=int, default=None, help="F_max of the fixed and adaptive windows.")
@click.option("--d-thr", "d_thr", default=None, help="d_thr values of the guided runs, comma-separated.")
@click.option("--resolution", default="320x240", show_default=True)
@click.option("--spp", type=int, default=RENDER_SPP, show_default=True, help=_RENDER_SPP_HELP)
@click.option("--reference-factor", type=int, default=50, show_default=True,
              help="Reference photons a frame as a multiple of the largest budget (at least 50).")
@click.option("--aqm-every", type=int, default=None, help="d_AQM on every n-th frame (and the change's).")
@click.option("--workers", type=int, default=2, show_default=True)
@click.option("--methods", default=None, help="Methods to run, comma-separated: per-frame (always), fixed, "
              "adaptive, guided (default: all).")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="Folder of error.json, error.png and error.svg (default: bench-error-SCENE).")
@click.option("--config", "config_file", type=click.Path(dir_okay=False), default=None,
              help="JSON object of RenderConfig fields (pipeline/config.py) for every run but the reference.")
def bench_error(scene, quick, frames, budgets, fmax, d_thr, resolution, spp, reference_factor, aqm_every, workers,
                methods, out_dir, config_file):
    """Run time against error vs a converged per-frame reference: per-frame, fixed and adaptive windows at
    several budgets, the guided coordinator at several d_thr (default: ROOM)."""
    from pathlib import Path

    from pipeline.benchmarks.error import FULL, METHODS, QUICK, Plan, run
    from pipeline.config import RenderConfig, load_config
    from pipeline.errors import LoomError
    from pipeline.run.render import parse_resolution

    name = Path(scene).stem if Path(scene).suffix else scene
    plans = QUICK if quick else FULL
    plan = plans.get(name, plans["cornell"])  # other scenes: CORNELL's budgets, frames from --frames
    if name not in plans and not frames:
        raise LoomError("give the frames to render (FIRST-LAST) for a scene without a plan", field="--frames")
    changes: dict = {"reference_factor": reference_factor}
    changes["width"], changes["height"] = parse_resolution(resolution)
    changes["spp"] = spp
    try:
        if frames:
            a, b = frames.split("-")
            changes["frames"] = (int(a), int(b))
        if budgets:
            changes["budgets"] = tuple(int(n) for n in budgets.split(","))
        if d_thr:
            changes["d_thr"] = tuple(float(d) for d in d_thr.split(","))
    except ValueError as err:
        raise LoomError(f"cannot read the list: {err}", field="--frames/--budgets/--d-thr") from None
    if fmax is not None:
        changes["fmax"] = fmax
    if methods:
        chosen = {m.strip() for m in methods.split(",") if m.strip()} | {"per-frame"}
        if chosen - set(METHODS):
            raise LoomError(f"unknown method(s) {', '.join(sorted(chosen - set(METHODS)))}; choose from "
                            f"{', '.join(METHODS)}", field="--methods")
        changes["methods"] = tuple(m for m in METHODS if m in chosen)
    if aqm_every is not None:
        if aqm_every < 1:
            raise LoomError(f"must be >= 1, got {aqm_every}", field="--aqm-every")
        changes["aqm_every"] = aqm_every
    if any(n <= 0 for n in changes.get("budgets", plan.budgets)):
        raise LoomError("budgets must be positive photon counts", field="--budgets")
    plan = Plan(**{**plan.__dict__, **changes})
    config = RenderConfig.from_dict(load_config(config_file)) if config_file else RenderConfig()
    run(scene, plan, Path(out_dir or f"bench-error-{name}"), workers=workers, config=config)


@bench.command("spp")
@click.option("--frames", default="68,23", show_default=True, help="ROOM frames, comma-separated.")
@click.option("--spp", "spps", default="1,2,4,8,16", show_default=True, help="Camera samples per pixel compared.")
@click.option("--reference-spp", type=click.IntRange(1), default=256, show_default=True,
              help="Samples per pixel of the converged reference.")
@click.option("--photons", type=click.IntRange(1), default=160_000, show_default=True,
              help="N_frame of the fixed indirect map.")
@click.option("--fmax", type=click.IntRange(0), default=30, show_default=True, help="F_max of the map's windows.")
@click.option("--resolution", default="320x240", show_default=True)
@click.option("--seed-check/--no-seed-check", default=True, show_default=True,
              help="Also compare a second reference (another seed) with the first: the table's floor.")
@click.option("--adaptive", "adaptive", default="4,8", show_default=True,
              help="Mean samples a pixel of the two-pass prototype, comma-separated (empty: none).")
@click.option("--store", default=None, help="Directory to keep the scene and photons in (default: a temporary one).")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None, help="Also write the figures here.")
def bench_spp(frames, spps, reference_spp, photons, fmax, resolution, seed_check, adaptive, store, json_path):
    """FLIP and d_AQM of ROOM frames at 1-16 camera samples per pixel against a converged reference, the
    indirect map fixed, and the compositing time per frame (docs/10-sampling.md)."""
    from pipeline.benchmarks.spp import run
    from pipeline.errors import LoomError
    from pipeline.run.render import parse_resolution

    width, height = parse_resolution(resolution)
    try:
        frame_list = tuple(int(f) for f in frames.split(",") if f.strip())
        spp_list = tuple(int(s) for s in spps.split(",") if s.strip())
        budgets = tuple(int(s) for s in adaptive.split(",") if s.strip())
    except ValueError as err:
        raise LoomError(f"cannot read the list: {err}", field="--frames/--spp") from None
    if not frame_list or not spp_list or min(spp_list) < 1:
        raise LoomError("give at least one frame and positive spp values", field="--frames/--spp")
    if budgets and min(budgets) < 3:
        raise LoomError("adaptive budgets start at 3 samples a pixel (2 in the first pass)", field="--adaptive")
    run(frame_list, spps=spp_list, reference_spp=reference_spp, photons=photons, fmax=fmax, width=width,
        height=height, seed_check=seed_check, adaptive=budgets, store=store, json_path=json_path, echo=click.echo)


@bench.command("elements")
@click.argument("scene", default="room")
@click.option("--frames", default="23,68,113", show_default=True, help="Frames compared, comma-separated.")
@click.option("--scales", default="0.5,0.75,1,1.5", show_default=True,
              help="Element sizes as multiples of the scene's, comma-separated; the smallest is the comparison.")
@click.option("--photons", type=click.IntRange(1), default=16_000_000, show_default=True,
              help="Photons a frame of every converged map.")
@click.option("--element-size", type=float, default=None,
              help="The element size the scales multiply (default: the scene's own).")
@click.option("--resolution", default="320x240", show_default=True)
@click.option("--spp", type=int, default=RENDER_SPP, show_default=True, help=_RENDER_SPP_HELP)
@click.option("--scheduler", default="local", show_default=True, help="synchronous, local or an address.")
@click.option("--workers", type=int, default=2, show_default=True)
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="Folder of elements.json and elements.png (default: bench-elements-SCENE).")
def bench_elements(scene, frames, scales, photons, element_size, resolution, spp, scheduler, workers, out_dir):
    """The element mesh's bias in the frames: converged maps on coarser and finer elements, each composited
    with the same camera paths and compared with the finest as the viewer sees it (docs/04-photons.md §8)."""
    from pathlib import Path

    from pipeline.benchmarks.elements import run
    from pipeline.errors import LoomError
    from pipeline.run.render import parse_resolution

    width, height = parse_resolution(resolution)
    try:
        frame_list = tuple(int(f) for f in frames.split(",") if f.strip())
        scale_list = tuple(float(s) for s in scales.split(",") if s.strip())
    except ValueError as err:
        raise LoomError(f"cannot read the list: {err}", field="--frames/--scales") from None
    if not frame_list:
        raise LoomError("give at least one frame", field="--frames")
    run(scene, frames=frame_list, scales=scale_list, photons=photons, width=width, height=height, spp=spp,
        element_size=element_size, scheduler=scheduler, workers=workers, out_dir=Path(out_dir) if out_dir else None,
        echo=click.echo)
