"""Frame files through OpenImageIO and the preview video through imageio-ffmpeg.

* ``beauty.####.exr``: linear Rec.709, 32-bit float, zip-compressed, one multichannel image with
  channels ``R,G,B,A`` (beauty) then ``albedo.R..``, ``direct.R..``, ``indirect.R..``, and metadata
  ``photonloom:*`` (scene, frame, camera, photons, config and render hashes).
* ``beauty.####.png``: the tone-mapped 8-bit sRGB picture.
* ``preview.mp4``: H.264 (yuv420p) from the PNGs, one video frame per rendered frame.

Every file is written under a temporary name in its directory and moved into place with
``os.replace``, so a killed task leaves either the old file or the new one, never a torn one
(OIIO picks its writer by extension, hence ``ImageOutput.create(format)``; docs/16-libraries.md §3).
"""
from __future__ import annotations

import os
import subprocess
import tempfile
from pathlib import Path
from typing import Iterable

import numpy as np
import OpenImageIO as oiio

LAYERS = ("albedo", "direct", "indirect")  # the order OpenEXR stores them in (sorted names)
EXR_CHANNELS = ("R", "G", "B", "A") + tuple(f"{layer}.{c}" for layer in LAYERS for c in "RGB")
LINEAR = "lin_rec709_scene"  # OIIO 3.2 colour interop id of linear Rec.709
SRGB = "srgb_rec709_scene"
META_PREFIX = "photonloom:"


def frame_paths(out_dir: str | Path, frame: int) -> tuple[Path, Path]:
    """The EXR and PNG of a frame (4-digit zero padding, ``####`` in farm notation)."""
    out = Path(out_dir)
    return out / f"beauty.{frame:04d}.exr", out / f"beauty.{frame:04d}.png"


def _partial(path: Path) -> Path:
    return path.with_name(f".{path.name}.{os.getpid()}.partial")


def _write(path: Path, fmt: str, spec: oiio.ImageSpec, pixels: np.ndarray) -> None:
    tmp = _partial(path)
    out = oiio.ImageOutput.create(fmt)
    if out is None:
        raise RuntimeError(f"OpenImageIO has no {fmt} writer: {oiio.geterror()}")
    try:
        if not out.open(str(tmp), spec) or not out.write_image(pixels):
            raise OSError(f"cannot write {path}: {out.geterror()}")
    finally:
        out.close()
    os.replace(tmp, path)


def write_exr(path: str | Path, beauty: np.ndarray, alpha: np.ndarray, layers: dict, metadata: dict) -> None:
    """Write the multichannel float32 EXR atomically (channels :data:`EXR_CHANNELS`).

    float32, not half: the maps and shading are float32, and half overflows to +Inf above 65504 and
    flushes to 0 below 6e-8 (a light 1e10 or 1e-10 times as bright, tests/stress/test_scale.py),
    and keeps 3 digits; one pixel type for every frame of an animation (docs/09-frames.md §2)."""
    h, w = alpha.shape
    pixels = np.concatenate([beauty, alpha[..., None]] + [layers[name] for name in LAYERS], axis=2)
    spec = oiio.ImageSpec(w, h, len(EXR_CHANNELS), "float")
    spec.channelnames = EXR_CHANNELS
    spec.alpha_channel = 3
    # zlib level 1 instead of OpenEXR's default 4: 34 against 42 ms a 320x240 frame, 1 % more bytes
    spec.attribute("compression", "zip:1")
    spec.attribute("oiio:ColorSpace", LINEAR)
    spec.attribute("DateTime", "")  # no wall-clock stamp: equal renders give equal files
    for key, value in metadata.items():
        spec.attribute(META_PREFIX + key, value if isinstance(value, (int, float)) else str(value))
    _write(Path(path), "openexr", spec, np.ascontiguousarray(pixels, np.float32))


def write_png(path: str | Path, rgb8: np.ndarray) -> None:
    """Write an 8-bit sRGB PNG atomically."""
    h, w = rgb8.shape[:2]
    spec = oiio.ImageSpec(w, h, 3, "uint8")
    spec.attribute("oiio:ColorSpace", SRGB)
    spec.attribute("png:compressionLevel", 1)  # zlib level 1: half the time of the default 6, +25 % bytes
    _write(Path(path), "png", spec, np.ascontiguousarray(rgb8, np.uint8))


def read_exr(path: str | Path) -> tuple[dict, dict]:
    """({channel name: (H, W) float32}, {metadata key without prefix: value}) of an EXR."""
    buf = oiio.ImageBuf(str(path))
    if buf.has_error:
        raise OSError(buf.geterror())
    spec = buf.spec()
    pixels = buf.get_pixels(oiio.FLOAT)
    if buf.has_error or pixels is None:
        raise OSError(buf.geterror())
    channels = {name: pixels[..., i] for i, name in enumerate(spec.channelnames)}
    meta = {a.name[len(META_PREFIX):]: a.value for a in spec.extra_attribs
            if a.name.startswith(META_PREFIX)}
    return channels, meta


def exr_metadata(path: str | Path) -> dict:
    """The ``photonloom:*`` metadata of an EXR (header only), {} if it cannot be read."""
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        return {}
    try:
        return {a.name[len(META_PREFIX):]: a.value for a in inp.spec().extra_attribs
                if a.name.startswith(META_PREFIX)}
    finally:
        inp.close()


def frame_is_valid(exr: str | Path, png: str | Path, width: int, height: int, frame_hash: str) -> bool:
    """Whether a frame is done: both files exist, decode, have the expected size and channels,
    and the EXR carries ``frame_hash`` (pipeline/run/coordinator.frame_hash: the same settings, map
    and exposure)."""
    if not (Path(exr).is_file() and Path(png).is_file()):
        return False
    try:
        channels, meta = read_exr(exr)
        img = oiio.ImageBuf(str(png))
        spec = img.spec()
        ok_png = (not img.has_error and (spec.width, spec.height, spec.nchannels) == (width, height, 3)
                  and img.get_pixels(oiio.UINT8) is not None and not img.has_error)
    except OSError:
        return False
    first = next(iter(channels.values()), None)
    return (ok_png and set(channels) == set(EXR_CHANNELS) and first is not None
            and first.shape == (height, width) and meta.get("frame_hash") == frame_hash)


def read_png(path: str | Path) -> np.ndarray:
    buf = oiio.ImageBuf(str(path))
    pixels = buf.get_pixels(oiio.UINT8)
    if buf.has_error or pixels is None:
        raise OSError(buf.geterror())
    return pixels


def write_video(pngs: Iterable[str | Path], path: str | Path, fps: float) -> int:
    """Assemble the PNGs into an H.264 MP4 atomically; returns the frame count.

    ffmpeg gets the PNG files' bytes through a pipe and decodes them itself (image2pipe), so this
    process only copies bytes and the encode runs beside the report's figures (pipeline/run/render.py).
    x264's ultrafast preset at CRF 18 (the usual "visually lossless" setting for a preview): on
    ROOM's 135 frames at 320x240, 0.33 s and 0.59 MB, against 0.58 s and 0.68 MB for veryfast at
    CRF 10, where ffmpeg's PNG decoding alone takes 0.31 s. x264 in one thread: the decoding (in
    ffmpeg's own threads) is most of the work, and x264's threads only added CPU (135 frames: 0.28
    against 0.31 CPU s at 320x240, 3.97 against 4.07 at 1280x960, wall no longer). An odd width or
    height is padded by one black column or row (yuv420p needs even sizes).
    """
    import imageio_ffmpeg  # only for the preview video

    path, pngs = Path(path), list(pngs)
    if not pngs:
        return 0
    tmp = _partial(path)
    # -xerror: a PNG ffmpeg cannot decode stops it (it would drop the frame and exit 0)
    cmd = [imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-nostdin", "-loglevel", "error", "-xerror",
           "-f", "image2pipe", "-framerate", f"{fps:g}", "-c:v", "png", "-i", "-",
           "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-c:v", "libx264", "-preset", "ultrafast", "-crf", "18",
           "-threads", "1", "-pix_fmt", "yuv420p", "-movflags", "+faststart", "-f", "mp4", str(tmp)]
    with tempfile.TemporaryFile() as log:  # a file, not a pipe: ffmpeg's messages never block it
        proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=log)
        try:
            try:
                for png in pngs:
                    proc.stdin.write(Path(png).read_bytes())
                proc.stdin.close()
            except BrokenPipeError:
                pass  # ffmpeg stopped early; its return code and log say why
            code = proc.wait()
        except BaseException:
            proc.kill()
            proc.wait()
            tmp.unlink(missing_ok=True)
            raise
        if code != 0:
            tmp.unlink(missing_ok=True)
            log.seek(0)
            reason = " ".join(log.read().decode(errors="replace").split())[-300:]
            raise OSError(f"ffmpeg could not write {path} (exit {code}): {reason}")
    os.replace(tmp, path)
    return len(pngs)
