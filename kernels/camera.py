"""Camera rays with pixel jitter for the compositor: ``camera8`` in camera.cl and its NumPy twin.

Sample ``c`` belongs to pixel ``c // spp``; its jitter is a splitmix64 hash of (frame key, c), the
two halves of one 64-bit word giving x and y (pipeline/frames/random_numbers.py, dimension 0). Directions are
float32 through a pinhole camera looking down -Z with +Y up and the vertical field of view.
"""
from __future__ import annotations

import numpy as np

from .context import LANES, WORK_GROUP, device_output, read_back


def mix64(x: np.ndarray) -> np.ndarray:
    """splitmix64 finaliser on uint64 arrays (wrapping arithmetic)."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def _axes(rot: np.ndarray) -> np.ndarray:
    """The camera's unit right, up and back axes as float32 columns of a 3x3 matrix."""
    return (rot / np.linalg.norm(rot, axis=0)).astype(np.float32)


def image_plane(key: int, c0: int, count: int, spp: int, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) float64 of samples c0 .. c0 + count - 1 on the image, jittered as ``camera8`` jitters
    them, each from -1 to 1 across the frame (x right, y up): the pinhole's directions scale them
    by the tangents, an orthographic camera's origins by its half extents."""
    counter = np.arange(c0, c0 + count, dtype=np.int64)
    h = mix64(mix64(counter.astype(np.uint64) ^ np.uint64(key)))  # dimension 0 adds nothing
    scale = 1.0 / (1 << 32)
    jx = (h >> np.uint64(32)).astype(np.float64) * scale
    jy = (h & np.uint64(0xFFFFFFFF)).astype(np.float64) * scale
    pixel = counter // spp
    px, py = pixel % width + jx, pixel // width + jy
    return (2.0 / width) * px - 1.0, 1.0 - (2.0 / height) * py


def camera_rays_reference(key: int, c0: int, count: int, spp: int, width: int, height: int,
                          yfov: float, rot: np.ndarray) -> np.ndarray:
    """(count, 3) float32 unit directions of samples c0 .. c0 + count - 1."""
    a, b = image_plane(key, c0, count, spp, width, height)
    tan_y = np.tan(yfov / 2.0)
    x = (a * (tan_y * width / height)).astype(np.float32)
    y = (b * tan_y).astype(np.float32)
    r = _axes(rot)
    d = np.empty((count, 3), np.float32)
    for k in range(3):
        d[:, k] = x * r[k, 0] + y * r[k, 1] - r[k, 2]
    norm = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])
    return d / norm[:, None]


def camera_rays_cl(key: int, c0: int, count: int, spp: int, width: int, height: int, yfov: float,
                   rot: np.ndarray) -> np.ndarray:
    """``camera8`` on PoCL: the same directions as :func:`camera_rays_reference`."""
    from .context import device_context, kernel  # imports pyopencl: only when a kernel runs

    ctx, queue = device_context()
    out = np.empty((count, 3), np.float32)
    if count == 0:
        return out
    items = -(-count // LANES)
    padded = -(-items // WORK_GROUP) * WORK_GROUP
    buf = device_output(ctx, out)
    tan_y = np.tan(yfov / 2.0)
    r = _axes(rot)
    kernel("camera", "camera8")(
        queue, (padded,), (WORK_GROUP,), np.int64(c0), np.int64(count), np.uint64(key), np.int32(width),
        np.int32(height), np.int32(spp), np.float64(tan_y * width / height), np.float64(tan_y),
        *(np.float32(v) for v in r.ravel()), buf)
    read_back(queue, [out], [buf])
    return out
