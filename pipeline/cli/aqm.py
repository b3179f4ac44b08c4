"""``loom aqm``: compare two frames with the Animation Quality Metric.

A thin wrapper: file I/O and options here, the metric in :mod:`pipeline.aqm` (its benchmark, ``loom
bench aqm``, in pipeline/benchmarks/aqm.py).
"""
from __future__ import annotations

from typing import Any, Callable, TypeVar

import click
import numpy as np

from pipeline.aqm import (
    AQM_SIZE,
    DISPLAYS,
    G_SP,
    Motion,
    ViewingConditions,
    aqm,
    aqm_geometry,
    pixels_per_frame_to_deg_per_s,
)
from pipeline.aqm.display import FILLS
from pipeline.aqm.visualize import difference_picture
from pipeline.errors import LoomError

_DEFAULT = ViewingConditions()
# What a click decorator takes and gives back: a function or a command
_F = TypeVar("_F", bound=Callable[..., Any])


def read_image(path: str, *, channels: str = "image") -> np.ndarray:
    """Read an image file with OpenImageIO as float64 (H, W, C); LoomError naming the file if unreadable."""
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(path)
    if inp is None:
        raise LoomError(oiio.geterror().replace("\n", " ") or "cannot open", path=path, field="file")
    try:
        pixels = inp.read_image(oiio.FLOAT)
        error = inp.geterror()
    finally:
        inp.close()
    if pixels is None or error:
        raise LoomError(f"cannot read pixels: {error.strip() or 'unknown error'}".replace("\n", " "),
                        path=path, field="file")
    pixels = np.asarray(pixels, dtype=np.float64)
    if pixels.ndim == 2:
        pixels = pixels[..., None]
    if channels == "image":
        if pixels.shape[2] == 2:
            raise LoomError("expected 1 (luminance) or >= 3 (RGB) channels, got 2", path=path, field="channels")
        return pixels[..., :3] if pixels.shape[2] >= 3 else pixels
    return pixels[..., :2] if pixels.shape[2] >= 2 else pixels[..., 0]  # flow: (vx, vy) or speed


def write_png(path: str, rgb8: np.ndarray) -> None:
    """Write an 8-bit RGB image; LoomError naming the file on failure."""
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(path)
    if out is None:
        raise LoomError(oiio.geterror().replace("\n", " ") or "cannot create", path=path, field="file")
    spec = oiio.ImageSpec(rgb8.shape[1], rgb8.shape[0], 3, oiio.UINT8)
    ok = out.open(path, spec) and out.write_image(np.ascontiguousarray(rgb8))
    error = out.geterror()
    out.close()
    if not ok:
        raise LoomError(f"cannot write: {error}".replace("\n", " "), path=path, field="file")


def _resolution(_ctx, _param, value: str | None) -> tuple[int, int] | None:
    if value is None:
        return None
    try:
        w, h = (int(v) for v in value.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"expected WIDTHxHEIGHT, got {value!r}") from None
    return w, h


def viewing_options(f: _F) -> _F:
    """The ViewingConditions options of ``loom aqm``: a named display, or its size, resolution and distance."""
    options = [
        click.option("--display", type=click.Choice(sorted(DISPLAYS)), default=None,
                     help="A named display (ColorVideoVDP's models); the options below override its fields. "
                          "Default: standard_fhd geometry at 100 cd/m^2."),
        click.option("--fill", type=click.Choice(FILLS), default=_DEFAULT.fill, show_default=True,
                     help="How a frame is shown: scaled to fill the display, or one frame pixel per display pixel."),
        click.option("--display-width", type=float, default=None,
                     help=f"Display width in metres [default: {_DEFAULT.display_width_m}]."),
        click.option("--display-resolution", default=None, callback=_resolution,
                     help="Display resolution WIDTHxHEIGHT in pixels [default: {}x{}].".format(*_DEFAULT.resolution)),
        click.option("--viewing-distance", type=float, default=None,
                     help=f"Viewing distance in metres [default: {_DEFAULT.viewing_distance_m}]."),
        click.option("--peak-luminance", type=float, default=None,
                     help=f"cd/m^2 shown for linear value 1.0 [default: {_DEFAULT.peak_luminance:g}]."),
        click.option("--black-level", type=float, default=None,
                     help=f"cd/m^2 shown for linear value 0.0 [default: {_DEFAULT.black_level:g}]."),
        click.option("--aqm-size", type=int, default=AQM_SIZE, show_default=True,
                     help="Longer side of the images the AQM works on (§6)."),
    ]
    for option in reversed(options):
        f = option(f)
    return f


def _viewing(display, fill, display_width, display_resolution, viewing_distance, peak_luminance, black_level):
    fields = {"display_width_m": display_width, "resolution": display_resolution,
              "viewing_distance_m": viewing_distance, "peak_luminance": peak_luminance,
              "black_level": black_level, "fill": fill}
    fields = {k: v for k, v in fields.items() if v is not None}
    return ViewingConditions.named(display, **fields) if display else ViewingConditions(**fields)


@click.command("aqm")
@click.argument("image_a", type=click.Path(dir_okay=False))
@click.argument("image_b", type=click.Path(dir_okay=False))
@click.option("--flow", "flow_path", type=click.Path(dir_okay=False), default=None,
              help="Image velocity of A's pixels from camera motion: 2 channels (vx, vy) or 1 (speed).")
@click.option("--flow-units", type=click.Choice(["deg/s", "px/frame"]), default="deg/s", show_default=True)
@click.option("--fps", type=float, default=None, help="Frames per second (needed with --flow-units px/frame).")
@click.option("--pursuit-gain", type=click.FloatRange(0.0, 1.0), default=G_SP, show_default=True,
              help="Smooth-pursuit gain for the flow: 0 eye does not follow, 1 tracks it (Daly 1998: 0.82).")
@viewing_options
@click.option("--map", "map_path", type=click.Path(dir_okay=False), default=None,
              help="Write M_AQM as a PNG: red where a difference is visible, over a grey A (Fig. 3d).")
def aqm_command(image_a, image_b, flow_path, flow_units, fps, pursuit_gain, display, fill, display_width,
                display_resolution, viewing_distance, peak_luminance, black_level, aqm_size, map_path):
    """Predict where a viewer sees a difference between linear-light frames IMAGE_A and IMAGE_B; print d_AQM."""
    viewing = _viewing(display, fill, display_width, display_resolution, viewing_distance, peak_luminance,
                       black_level)
    a = read_image(image_a)
    b = read_image(image_b)
    flow = None
    if flow_path is not None:
        flow = read_image(flow_path, channels="flow")
        if flow_units == "px/frame":
            if fps is None or not fps > 0:
                raise LoomError("--flow-units px/frame needs a positive --fps", path=flow_path, field="fps")
            flow = pixels_per_frame_to_deg_per_s(flow, fps, viewing.frame_ppd(a.shape[:2]))
    motion = None if flow is None else Motion(flow, pursuit_gain, flow_path)
    result = aqm(a, b, motion=motion, viewing=viewing, aqm_size=aqm_size, names=(image_a, image_b))
    h, w = result.map.shape
    click.echo(aqm_geometry(viewing, a.shape[:2], aqm_size).describe(viewing))
    click.echo(f"d_AQM = {result.d_aqm:.3f} % of {h * w} pixels above 1 JND (P > {result.threshold}); "
               f"AQM at {w}x{h}, {result.ppd:.2f} px/deg")
    if map_path is not None:
        write_png(map_path, difference_picture(a, result.visible))
