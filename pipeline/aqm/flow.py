"""Per-pixel image velocity from camera motion by 3-D warping (§6 of the paper; Myszkowski et al. 1999).

Each pixel of frame f is lifted to its world-space point with the frame's depth and camera, then
projected with the camera of a neighbouring frame; the displacement in pixels per frame, times fps
and divided by pixels per degree, is the image velocity in deg/s (docs/08-aqm.md §2b). Only the camera
moves: animated objects are assumed tracked by the eye (§6), so their own motion is left out, and the
flow is that of a static world seen by the moving camera.

Conventions (docs/03-conventions.md §3): cameras look down -Z with +Y up; ``world_to_camera`` is a 4x4 matrix;
the projection is a pinhole with vertical field of view ``yfov`` (radians) over the depth image's
rows, or orthographic (:class:`Ortho`: parallel rays, a view ``2 ymag`` high); ``depth`` is the
positive distance along the viewing axis (-z in camera space), +inf for pixels that see nothing
(sky), which a pinhole warps as directions and an orthographic camera does not move.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Union

import numpy as np
import numpy.typing as npt

from ..errors import LoomError


def _check_camera(matrix, name: str) -> np.ndarray:
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise LoomError(f"expected a finite 4x4 world-to-camera matrix, got shape {m.shape}", field=name)
    return m


def _check_depth(depth) -> np.ndarray:
    d = np.asarray(depth, dtype=np.float64)
    if d.ndim != 2:
        raise LoomError(f"expected a 2-D depth image, got shape {d.shape}", field="depth")
    if np.isnan(d).any() or (d <= 0).any():
        raise LoomError("depth must be positive (or +inf for empty pixels), found NaN or <= 0", field="depth")
    return d


@dataclass(frozen=True)
class Ortho:
    """An orthographic camera's lens: a view ``2 ymag`` high (world units), the width by the aspect."""

    ymag: float


Lens = Union[float, Ortho]  # a pinhole's vertical field of view (radians), or an orthographic view


def focal_pixels(height: int, yfov: float) -> float:
    """Pinhole focal length in pixels for a vertical field of view ``yfov`` (radians) over ``height`` rows."""
    return 0.5 * height / np.tan(0.5 * yfov)


def unproject(depth: np.ndarray, yfov: Lens) -> np.ndarray:
    """Homogeneous camera-space points (H, W, 4) of each pixel centre; w = 0 for infinite depth."""
    h, w = depth.shape
    ortho = isinstance(yfov, Ortho)
    f = 0.5 * h / yfov.ymag if ortho else focal_pixels(h, yfov)  # pixels per unit across, at unit depth
    x = (np.arange(w) + 0.5 - 0.5 * w) / f
    y = -(np.arange(h) + 0.5 - 0.5 * h) / f
    finite = np.isfinite(depth)
    scale = np.where(finite, depth, 1.0)
    across = 1.0 if ortho else scale  # a pinhole's rays spread with depth, an orthographic camera's do not
    pts = np.empty((h, w, 4))
    pts[..., 0] = x[None, :] * across
    pts[..., 1] = y[:, None] * across
    pts[..., 2] = -scale
    pts[..., 3] = finite
    return pts


def project(points: np.ndarray, shape: tuple[int, int], yfov: Lens) -> np.ndarray:
    """Continuous pixel coordinates (..., 2) = (column, row) of camera-space points; NaN behind the camera."""
    h, w = shape
    z = -points[..., 2]
    if isinstance(yfov, Ortho):
        f, spread = 0.5 * h / yfov.ymag, 1.0
    else:
        f, spread = focal_pixels(h, yfov), z
    with np.errstate(divide="ignore", invalid="ignore"):
        u = 0.5 * w + f * points[..., 0] / spread
        v = 0.5 * h - f * points[..., 1] / spread
    out = np.stack([u, v], axis=-1)
    out[z <= 0] = np.nan
    return out


def warp_displacement(depth: npt.ArrayLike, world_to_camera: npt.ArrayLike, other_world_to_camera: npt.ArrayLike,
                      yfov: Lens, other_yfov: Lens | None = None) -> np.ndarray:
    """Displacement (H, W, 2) in pixels of each pixel when seen by the other camera (its field of
    view ``other_yfov``, default ``yfov``: a zoom moves pixels too); NaN if behind it. Through an
    orthographic lens a pixel that sees nothing does not move (every such pixel sees the same sky)."""
    d = _check_depth(depth)
    cam = _check_camera(world_to_camera, "world_to_camera")
    other = _check_camera(other_world_to_camera, "other_world_to_camera")
    pts = unproject(d, yfov)
    warp = other @ np.linalg.inv(cam)  # camera f -> world -> camera g
    moved = pts @ warp.T
    shift = project(moved, d.shape, yfov if other_yfov is None else other_yfov) - project(pts, d.shape, yfov)
    if isinstance(yfov, Ortho):
        shift[~np.isfinite(d)] = 0.0
    return shift


Neighbour = Union[npt.ArrayLike, tuple[npt.ArrayLike, Lens]]


def image_velocity(depth: npt.ArrayLike, world_to_camera: npt.ArrayLike, *, yfov: Lens, fps: float, ppd: float,
                   previous: Neighbour | None = None, following: Neighbour | None = None) -> np.ndarray:
    """Image velocity (H, W, 2) in deg/s (x right, y down) of frame f from its neighbours' cameras.

    ``previous``/``following`` are the world-to-camera matrices of frames f-1 and f+1, or (matrix,
    yfov) pairs where a neighbour's field of view differs (a zoom); with both the velocity is the
    central difference, with one a one-sided difference. ``ppd`` is pixels per degree
    of the depth image as displayed (ViewingConditions.ppd). A pixel that falls behind a neighbour's
    camera uses the other neighbour; behind both, it gets 0 deg/s (fully visible: the conservative
    choice for a stopping criterion).
    """
    if previous is None and following is None:
        raise LoomError("needs the camera of at least one neighbouring frame", field="flow")
    if not (fps > 0 and ppd > 0):
        raise LoomError(f"fps and ppd must be positive, got {fps} and {ppd}", field="flow")
    steps = []
    if previous is not None:
        steps.append(-warp_displacement(depth, world_to_camera, *_view(previous, yfov)))
    if following is not None:
        steps.append(warp_displacement(depth, world_to_camera, *_view(following, yfov)))
    stack = np.stack(steps)
    valid = np.isfinite(stack).all(axis=-1, keepdims=True)
    count = valid.sum(axis=0)
    per_frame = np.where(valid, stack, 0.0).sum(axis=0) / np.maximum(count, 1)
    return pixels_per_frame_to_deg_per_s(per_frame, fps, ppd)


def _view(neighbour: Neighbour, yfov: Lens) -> tuple[npt.ArrayLike, Lens, Lens]:
    """(its world-to-camera matrix, this frame's lens, its lens) of a neighbour as image_velocity takes it."""
    if isinstance(neighbour, tuple):
        return neighbour[0], yfov, neighbour[1] if isinstance(neighbour[1], Ortho) else float(neighbour[1])
    return neighbour, yfov, yfov


def pixels_per_frame_to_deg_per_s(flow: np.ndarray, fps: float, ppd: float) -> np.ndarray:
    """v_I = delta_p * fps / ppd (docs/08-aqm.md §2b)."""
    return np.asarray(flow, dtype=np.float64) * (fps / ppd)
