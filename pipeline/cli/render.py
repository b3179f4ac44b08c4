"""``loom shoot``, ``loom render`` and what a render leaves to look at: ``loom segments``, ``loom report``.

The job options (what a render makes) are shared with ``loom plan`` (farm.py).
"""
from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any, Callable, TypeVar

import click

from pipeline.aqm.display import DISPLAYS as _DISPLAYS
from pipeline.config import PhotonConfig as _PhotonConfig

from .scene import ANIMATION_HELP, CAMERA_HELP, ENVIRONMENT_HELP, LIGHT_HELP, VARIANT_HELP

if TYPE_CHECKING:
    from pipeline.run.render import RenderRequest

_PHOTON_DEPTH = _PhotonConfig().photon_depth
_PHOTON_DEPTH_HELP = "Safety cap on photon hits (Russian roulette ends paths; pipeline/config.py)."
_KEEP_HELP = ("Also store every photon hit (20 bytes each, the paper's record) for re-estimation and research; "
              "a render reads only the per-batch counts and sums it always stores.")
# What a click decorator takes and gives back: a function or a command
_F = TypeVar("_F", bound=Callable[..., Any])


class _RenderSpp:
    """The default of every option that means a render's camera samples per pixel: RenderSettings.spp
    (pipeline/frames/settings.py), its one owner, read when click needs it, so that the CLI imports the
    frame stage only for a command that uses it: click calls it for the value and shows str() of it in
    --help (a plain function would show "(dynamic)")."""

    def __call__(self) -> int:
        from pipeline.frames.settings import RenderSettings

        return RenderSettings.spp

    def __str__(self) -> str:
        return str(self())


RENDER_SPP = _RenderSpp()


def scheduler_options(f: _F) -> _F:
    f = click.option("--workers", type=int, default=None,
                     help="Worker processes for --scheduler local (default: one per core).")(f)
    f = click.option("--scheduler", default="local", show_default=True,
                     help="local (embedded LocalCluster), synchronous, or a scheduler address "
                          "such as tcp://127.0.0.1:8786.")(f)
    return f


@click.command("shoot")
@click.argument("scene_file", type=click.Path(dir_okay=False))
@click.option("--frames", default=None, help="Farm range: 1-100, 1-100x2, 1,5,10-20 (default: all).")
@click.option("--photons", type=int, default=40_000, show_default=True, help="Photons per frame (N_frame).")
@click.option("--store", "store_url", required=True, help="Photon store: a directory or an fsspec URL.")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--element-size", type=float, default=None, help="Element edge bound (default: the scene's).")
@click.option("--photon-depth", type=int, default=_PHOTON_DEPTH, show_default=True, help=_PHOTON_DEPTH_HELP)
@click.option("--keep-records", is_flag=True, help=_KEEP_HELP)
@click.option("--quiet", is_flag=True, help="No progress bar, no notices of the defaults chosen.")
@click.option("--light", type=click.Choice(["auto", "none"]), default="auto", show_default=True, help=LIGHT_HELP)
@click.option("--animation", default=None, help=ANIMATION_HELP)
@click.option("--variant", default=None, help=VARIANT_HELP)
@scheduler_options
def shoot_command(scene_file, frames, photons, store_url, seed, element_size, photon_depth, keep_records, quiet,
                  light, animation, variant, scheduler, workers) -> None:
    """Trace photons for every frame of SCENE_FILE into a photon store (resumable)."""
    from pipeline.config import PhotonConfig
    from pipeline.run.shoot import plan, shoot
    from pipeline.scene import read_scene

    if quiet:
        _hush_notices()
    config = PhotonConfig(seed=seed, element_size=element_size, photon_depth=photon_depth)
    p = plan(read_scene(scene_file, light=light, animation=animation, variant=variant), frames, photons, config)
    summary = shoot(p, store_url, keep_records=keep_records, scheduler=scheduler, workers=workers,
                    progress=not quiet)
    click.echo(
        f"shot {summary['frames']} frames ({summary['traced_frames']} traced, {summary['shared_frames']} "
        f"sharing a traced frame's photons): {summary['tasks']} batches run, {summary['skipped']} already "
        f"done; {summary['photons']:,} photons, {summary['records']:,} records, {summary['rays']:,} rays "
        f"in {summary['seconds']:.1f} s -> {store_url}")


def _photons(_ctx, _param, value):
    if value is None or str(value).strip().lower() == "auto":
        return None
    try:
        n = int(str(value).replace(",", "").replace("_", ""))
    except ValueError:
        raise click.BadParameter(f"expected auto or a number of photons per frame, got {value!r}") from None
    if n <= 0:
        raise click.BadParameter(f"must be auto or a positive number of photons per frame, got {n}")
    return n


def job_options(f: _F) -> _F:
    """The options that say what a render makes (shared by ``loom render`` and ``loom plan``)."""
    options = [
        click.argument("scene_file", type=click.Path(dir_okay=False)),
        click.option("--frames", default=None, help="Farm range: 1-100, 1-100x2, 1,5,10-20 (default: all)."),
        click.option("--out", "out_dir", required=True, type=click.Path(), help="Output directory."),
        click.option("--resolution", default="640x480", show_default=True, help="WIDTHxHEIGHT in pixels."),
        click.option("--spp", type=int, default=RENDER_SPP, show_default=True,
                     help="Jittered camera samples per pixel (the default: the pixels' error no more visible "
                          "than the photon noise d_thr accepts, docs/10-sampling.md)."),
        click.option("--shutter", type=float, default=0.0, show_default=True,
                     help="Share of a frame interval the shutter is open, centred on the frame: motion blur "
                          "(0.5: film's 180-degree shutter), each of a pixel's samples at its own instant "
                          "(pipeline/frames/shutter.py). 0: no blur."),
        click.option("--photons", default="auto", show_default=True, callback=_photons,
                     help="N_frame: auto (chosen per segment by the AQM, §5.2) or photons per frame for every "
                          "frame."),
        click.option("--fmax", type=int, default=None,
                     help="F_max: of the first segment with --photons auto (§5.2.1), of every frame with "
                          "--photons N (default: fmax_initial, 15)."),
        click.option("--temporal", type=click.Choice(["adaptive", "fixed", "off"]), default="adaptive",
                     show_default=True, help="Temporal photon collection with --photons N: Condition (1) windows "
                     "(§5.1), always +-F_max/2 (§6), or each frame's own photons."),
        click.option("--store", "store_url", default=None, help="Photon store (default: OUT/photons.zarr)."),
        click.option("--keep-records", is_flag=True, help=_KEEP_HELP),
        click.option("--camera", default=None, help=CAMERA_HELP),
        click.option("--animation", default=None, help=ANIMATION_HELP),
        click.option("--variant", default=None, help=VARIANT_HELP),
        click.option("--environment", default=None, type=click.Path(dir_okay=False), help=ENVIRONMENT_HELP),
        click.option("--environment-strength", type=float, default=1.0, show_default=True,
                     help="Multiplies the environment map's radiance."),
        click.option("--environment-rotation", type=float, default=0.0, show_default=True,
                     help="Turns the environment map about +Y, degrees counter-clockwise seen from above."),
        click.option("--seed", type=int, default=0, show_default=True),
        click.option("--reflection-depth", type=int, default=4, show_default=True,
                     help="Mirror/glossy reflections followed per camera path."),
        click.option("--photon-depth", type=int, default=_PHOTON_DEPTH, show_default=True, help=_PHOTON_DEPTH_HELP),
        click.option("--d-thr", type=float, default=None,
                     help="d_thr, share of AQM pixels allowed above 1 JND (0.03)."),
        click.option("--config", "config_file", type=click.Path(dir_okay=False), default=None,
                     help="JSON object of RenderConfig fields (pipeline/config.py); the options above override it."),
        click.option("--light", type=click.Choice(["auto", "none"]), default="auto", show_default=True,
                     help=LIGHT_HELP),
        click.option("--tonemap", type=click.Choice(["filmic", "exposure", "ward"]), default="filmic",
                     show_default=True, help="How frames are shown: a filmic curve or a linear exposure keyed to the "
                     "eye's adaptation, or Ward's visibility-matching operator (pipeline/frames/tonemap.py)."),
        click.option("--exposure", type=float, default=0.0, show_default=True,
                     help="Exposure offset in EV (x 2^EV) on top of the operator's own."),
        click.option("--display", type=click.Choice(sorted(_DISPLAYS)), default="standard_fhd", show_default=True,
                     help="The display the AQM assumes the frames are watched on (ColorVideoVDP's models: size, "
                          "resolution, viewing distance); loom render prints the pixels per degree it gives."),
        click.option("--fill", type=click.Choice(["full_screen", "native"]), default="full_screen",
                     show_default=True, help="How a frame is shown on --display: scaled to fill it, or one frame "
                     "pixel per display pixel."),
        click.option("--element-size", type=float, default=None,
                     help="Element edge bound in world units (default: the scene's extras, else 1/50 of the "
                          "diagonal of the posed scene's bounds over the timeline; `loom info` shows it)."),
    ]
    for option in reversed(options):
        f = option(f)
    return f


def render_request(scene_file: str, frames: str | None, out_dir: str, resolution: str, spp: int,
                   photons: int | None, fmax: int | None, temporal: str, store_url: str | None, keep_records: bool,
                   camera: str | None, seed: int, reflection_depth: int, photon_depth: int, d_thr: float | None,
                   config_file: str | None, light: str = "auto", tonemap: str = "filmic", exposure: float = 0.0,
                   element_size: float | None = None, display: str = "standard_fhd",
                   fill: str = "full_screen", animation: str | None = None, shutter: float = 0.0,
                   variant: str | None = None, environment: str | None = None,
                   environment_strength: float = 1.0, environment_rotation: float = 0.0) -> RenderRequest:
    """The RenderRequest (pipeline/run/render.py) of the job options: one parameter per option."""
    from pipeline.config import RenderConfig, load_config
    from pipeline.frames.settings import RenderSettings
    from pipeline.frames.tonemap import ToneMapping
    from pipeline.run.render import RenderRequest, parse_resolution

    width, height = parse_resolution(resolution)
    fields = load_config(config_file) if config_file else {}
    fields.update(seed=seed, photon_depth=photon_depth, **({} if d_thr is None else {"d_thr": d_thr}),
                  **({} if element_size is None else {"element_size": element_size}))
    return RenderRequest(scene_path=scene_file, frames=frames, out_dir=out_dir, n_photons=photons, fmax=fmax,
                         temporal=temporal, store_url=store_url, keep_records=keep_records, camera=camera,
                         animation=animation, variant=variant, config=RenderConfig.from_dict(fields), light=light,
                         environment=(None if environment is None
                                      else (environment, environment_strength, environment_rotation)),
                         settings=RenderSettings(width=width, height=height, spp=spp,
                                                 reflection_depth=reflection_depth, shutter=shutter,
                                                 tonemap=ToneMapping(operator=tonemap, exposure=exposure,
                                                                     display=display, fill=fill)))


@click.command("render")
@job_options
@click.option("--segment", type=int, default=None,
              help="Redo one segment (index from `loom segments OUT`) and only the frames that depend on it.")
@click.option("--quiet", is_flag=True, help="No progress lines, no notices of the defaults chosen.")
@click.option("--verbose", is_flag=True, help="Log more of what the stages do.")
@click.option("--performance-report", type=click.Path(dir_okay=False), default=None,
              help="Write Dask's performance report of the run to this HTML file.")
@scheduler_options
def render_command(segment, quiet, verbose, performance_report, scheduler, workers, **job) -> None:
    """Render frames of SCENE_FILE: photons, segments, illumination maps, EXR/PNG frames, preview.mp4."""
    if scheduler == "local":  # the workers' fork server imports while this process does (pipeline/run/cluster.py)
        from pipeline.run.cluster import start_worker_server
        start_worker_server()
    from pipeline.run.render import render

    if verbose:
        logging.getLogger("pipeline").setLevel(logging.INFO)
    if quiet:
        _hush_notices()
    report = render(render_request(**job), scheduler=scheduler, workers=workers, segment=segment,
                    echo=None if quiet else click.echo, performance_report=performance_report)
    t, out_dir = report["times_s"], job["out_dir"]
    click.echo(f"rendered {len(report['rendered'])} frames ({len(report['skipped'])} already done) "
               f"at {report['resolution'][0]}x{report['resolution'][1]}, {report['spp']} spp in "
               f"{t['total_s']:.1f} s (photons {t['shoot_s']:.1f}, AQM {t['aqm_s']:.1f}, temporal "
               f"{t['temporal_s']:.1f}, composite {t['composite_s']:.1f}, video {t['video_s']:.1f}); "
               f"{len(report['segments'])} segment(s)")
    from pipeline.report.tables import store_size_line

    click.echo(store_size_line(report["store_size"]))
    click.echo(f"frames: {out_dir}/beauty.####.exr, .png  video: {report['video']}  "
               f"report: {out_dir}/report.json  segments: loom segments {out_dir}")
    click.echo(f"report: {out_dir}/report.html")


def _hush_notices() -> None:
    """--quiet: the loader's notices of the defaults it chose are announcements too, like the
    progress lines; its warnings and errors still print."""
    logging.getLogger("pipeline.scene.notices").setLevel(logging.WARNING)


@click.command("segments")
@click.argument("out_dir", type=click.Path(file_okay=False))
@click.option("--json", "as_json", is_flag=True, help="The records as JSON.")
@click.option("--plot", "plot_file", type=click.Path(dir_okay=False), default=None,
              help="Also draw d_AQM against N_frame (Fig. 6) and p_me against F_max into this PNG.")
def segments_command(out_dir: str, as_json: bool, plot_file: str | None) -> None:
    """The segments of a render: the paper's Table 1 (K_i, N_frame, F_max) with d_AQM, p_me, times."""
    import json

    from pipeline.segments.records import read_records, table

    records = read_records(out_dir)
    if plot_file:
        from pipeline.report.segment_plot import plot_segments

        click.echo(f"wrote {plot_segments(records, plot_file)}", err=as_json)
    if as_json:
        click.echo(json.dumps([r.to_dict() for r in records], indent=1))
        return
    for line in table(records):
        click.echo(line)


@click.command("report")
@click.argument("out_dir", type=click.Path(file_okay=False))
def report_command(out_dir: str) -> None:
    """Write OUT/report.html: segments, costs, windows, AQM maps, frames, video, skips, settings (one file)."""
    from pipeline.report.page import write_report

    click.echo(f"wrote {write_report(out_dir)}")
