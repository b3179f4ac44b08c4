"""Image-based lighting: an equirectangular (latitude-longitude) radiance map at infinity (an HDRI).

``loom render --environment FILE`` surrounds the scene with the image's linear radiance (RGB, the
units of docs/03-conventions.md §1, times ``--environment-strength``), in place of the default sky.
Directions map to the image as Blender's world does (so an HDRI lights a file exported from Blender
as it lit the .blend): column u = atan2(Z, X) / 2 pi + 1/2, row v = 1/2 - asin(Y) / pi from the top
(glTF's +Y up), turned about +Y by ``--environment-rotation`` degrees (the right-hand rule,
counter-clockwise seen from above: a sun at -Z turned by 90 degrees shines from -X). A texel is a
constant radiance over its solid angle, sin(elevation) x longitude band (``texel_solid_angles``);
lookups take the texel a direction falls in.

Sampled by importance (pbrt-v4's image infinite light, piecewise constant): a texel with
probability proportional to its brightest channel times its solid angle, then a direction uniform
in its solid angle (longitude uniform, sin(elevation) uniform), so pdf(w) = p_texel / dOmega_texel
exactly and L / pdf is nearly constant over the map: a sun in the image is where the samples go.
The photon tracer emits by it (pipeline/photons/emission.py ``environment_photons``: weight
L / pdf x pi R^2 over the emitter's selection probability, from a disk of radius R facing the
direction, 1.05 R upstream, as the sky's photons), and the compositor's sky samples use it
(pipeline/frames/area_lights.py). Camera rays that leave the scene see the map.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pipeline.errors import SceneError

from .textures import srgb_to_linear

MAX_PIXELS = 1 << 26  # an 8192 x 4096 map, 400 MB as float32 RGB with its tables


@dataclass(frozen=True, eq=False)
class EnvironmentMap:
    """An equirectangular radiance map (H, W, 3) float32, and its importance-sampling tables."""

    image: np.ndarray = field(repr=False)
    digest: str  # of the file's bytes and the strength: which light a photon store was made under
    source: tuple[str, float, float] | None = None  # (absolute file, strength, rotation) it came from, for workers
    rotation: float = 0.0  # degrees about +Y, counter-clockwise seen from above
    _cdf: np.ndarray = field(init=False, repr=False)
    _pdf: np.ndarray = field(init=False, repr=False)  # (H * W,) per solid angle, of a direction in each texel

    def __post_init__(self) -> None:
        omega = texel_solid_angles(*self.image.shape[:2])
        weight = (self.image.max(axis=2) * omega).ravel().astype(np.float64)
        if not weight.sum() > 0:
            weight = omega.ravel().astype(np.float64)  # a black map: sample uniformly, it emits nothing
        p = weight / weight.sum()
        cdf = np.cumsum(p)
        cdf[-1] = 1.0
        object.__setattr__(self, "_cdf", cdf)
        object.__setattr__(self, "_pdf", p / omega.ravel())

    @property
    def size(self) -> tuple[int, int]:
        return self.image.shape[0], self.image.shape[1]

    def _turn(self, d: np.ndarray, sign: float) -> np.ndarray:
        """``d`` (n, 3) turned about +Y by ``sign`` x the rotation (+1: map to world, -1: world to map)."""
        if not self.rotation:
            return d
        a = sign * np.radians(self.rotation)
        c, s = np.cos(a), np.sin(a)
        return np.stack([c * d[:, 0] + s * d[:, 2], d[:, 1], -s * d[:, 0] + c * d[:, 2]], axis=1)

    def _texel(self, directions: np.ndarray) -> np.ndarray:
        d = self._turn(np.asarray(directions, np.float64), -1.0)
        h, w = self.size
        u = np.arctan2(d[:, 2], d[:, 0]) / (2.0 * np.pi) + 0.5
        v = 0.5 - np.arcsin(np.clip(d[:, 1] / np.maximum(np.linalg.norm(d, axis=1), 1e-30), -1.0, 1.0)) / np.pi
        j = np.minimum((u * w).astype(np.int64), w - 1) % w
        i = np.clip((v * h).astype(np.int64), 0, h - 1)
        return i * w + j

    def radiance(self, directions: np.ndarray) -> np.ndarray:
        """(n, 3) float32 radiance arriving from the map along rays leaving in ``directions``."""
        return np.take(self.image.reshape(-1, 3), self._texel(directions), axis=0)

    def pdf(self, directions: np.ndarray) -> np.ndarray:
        """(n,) float64 solid-angle density of :meth:`sample` at ``directions``."""
        return np.take(self._pdf, self._texel(directions))

    def sample(self, u0: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n, 3) unit directions towards the map from three uniform numbers each, and their pdf."""
        h, w = self.size
        texel = np.minimum(np.searchsorted(self._cdf, u0, side="right"), h * w - 1)
        i, j = texel // w, texel % w
        lo, hi = np.sin(np.pi * (0.5 - (i + 1) / h)), np.sin(np.pi * (0.5 - i / h))
        y = lo + np.asarray(u2) * (hi - lo)  # sin(elevation) uniform: uniform in the band's solid angle
        phi = 2.0 * np.pi * ((j + np.asarray(u1)) / w - 0.5)
        r = np.sqrt(np.maximum(1.0 - y * y, 0.0))
        return self._turn(np.stack([r * np.cos(phi), y, r * np.sin(phi)], axis=1), 1.0), np.take(self._pdf, texel)

    def power(self, radius: float) -> np.ndarray:
        """(3,) flux through a disk of ``radius`` from every direction: pi R^2 x the integral of L
        over the sphere (each direction's photons cross a disk facing it, kernels/emit.py's sky)."""
        omega = texel_solid_angles(*self.size)
        return (self.image.astype(np.float64) * omega[:, :, None]).sum(axis=(0, 1)) * np.pi * radius * radius

    def state(self) -> np.ndarray:
        """Numbers that identify the map (for state keys)."""
        return np.frombuffer(bytes.fromhex(self.digest[:32]), np.uint32).astype(np.float64)


def texel_solid_angles(h: int, w: int) -> np.ndarray:
    """(H, W) solid angle of each texel of an equirectangular map: 2 pi / W x the band's sin(elevation) span."""
    edges = np.sin(np.pi * (0.5 - np.arange(h + 1) / h))
    return np.repeat(((edges[:-1] - edges[1:]) * 2.0 * np.pi / w)[:, None], w, axis=1)


def load_environment(path: str | Path, strength: float = 1.0, rotation: float = 0.0) -> EnvironmentMap:
    """The map in ``path`` (EXR or HDR for radiance; an 8-bit image is read as sRGB-encoded), times
    ``strength``, turned by ``rotation`` degrees about +Y; a one-line error for a file that cannot be
    read or holds no usable radiance."""
    import OpenImageIO as oiio  # heavy: only where images are read

    path = Path(path)
    field_name = "--environment"
    if not np.isfinite(strength) or strength < 0:
        raise SceneError(f"strength must be a non-negative number, got {strength}", path=str(path),
                         field="--environment-strength")
    if not np.isfinite(rotation):
        raise SceneError(f"rotation must be a number of degrees, got {rotation}", path=str(path),
                         field="--environment-rotation")
    try:
        data = path.read_bytes()
    except OSError as err:
        raise SceneError(f"cannot read the environment map: {err.strerror or err}", path=str(path),
                         field=field_name) from None
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise SceneError(f"cannot decode the environment map: {oiio.geterror().strip() or 'unknown format'}",
                         path=str(path), field=field_name)
    try:
        spec = inp.spec()
        if spec.width * spec.height > MAX_PIXELS or spec.width < 2 or spec.height < 1:
            raise SceneError(f"{spec.width} x {spec.height} pixels: a map has 2 to {MAX_PIXELS:,}",
                             path=str(path), field=field_name)
        pixels = inp.read_image("float")
        low_range = spec.format.basetype in (oiio.UINT8, oiio.UINT16)
    finally:
        inp.close()
    if pixels is None or pixels.ndim != 3:
        raise SceneError("the environment map holds no pixels", path=str(path), field=field_name)
    rgb = np.repeat(pixels[:, :, :1], 3, axis=2) if pixels.shape[2] < 3 else pixels[:, :, :3]
    if low_range:  # an 8- or 16-bit image is display-encoded: back to linear (sRGB's curve)
        rgb = srgb_to_linear(np.clip(rgb, 0.0, 1.0))
    if not np.all(np.isfinite(rgb)) or rgb.min() < 0:
        raise SceneError("the environment map has negative, NaN or infinite radiance", path=str(path),
                         field=field_name)
    digest = hashlib.sha256(data + f"\0{strength!r}\0{rotation!r}".encode()).hexdigest()
    return EnvironmentMap((rgb * strength).astype(np.float32), digest,
                          (str(path.resolve()), float(strength), float(rotation)), float(rotation))
