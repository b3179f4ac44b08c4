"""What the viewer sees of a rendering: display values after this render's tone mapping (§5.2.3).

The AQM predicts visible differences between two *displayed* frames (Daly 1993 takes cd/m^2), so
the even/odd renderings I1(K), I2(K) are compared after Ward's visibility-matching tone mapping at
the frame's adaptation (pipeline/frames/tonemap.py): L_d = m(L_wa) L_w, clipped at the display's white
Ld_max, whatever look (``--tonemap``) the final frames are shown with. Comparing linear radiance as if 1.0 were
100 cd/m^2 instead judges a dim room as a bright
one (sensitivity rises with luminance) and never clips highlights, so it over-states the noise.
"""
from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from pipeline.aqm import AQM_SIZE, AQMResult, Motion, ViewingConditions, aqm, image_velocity
from pipeline.aqm.display import DISPLAYS, aqm_geometry
from pipeline.aqm.flow import Lens, Ortho
from pipeline.photons.raycast import caster_for

from .tonemap import ToneMapping, ward_scale

if TYPE_CHECKING:
    from pipeline.scene import Scene
    from pipeline.scene.camera import Camera


def display_values(rgb: np.ndarray, adaptation: float, params: ToneMapping = ToneMapping()) -> np.ndarray:
    """Linear display values (1.0 = the display's white, Ld_max) of linear radiance ``rgb`` shown at
    adaptation luminance ``adaptation`` (radiance units): the PNG's value before its sRGB encoding."""
    m = ward_scale(adaptation * params.nits_per_unit, params.display_max)
    return np.clip(np.asarray(rgb, np.float64) * (params.nits_per_unit * m / params.display_max), 0.0, 1.0)


def viewing_for(params: ToneMapping) -> ViewingConditions:
    """The AQM's viewing conditions: the named display's geometry (size, resolution, distance), the
    frame shown on it as ``params.fill`` says, and the display white the tone mapping maps to, with
    the display's contrast (docs/08-aqm.md §7)."""
    named = ViewingConditions.named(params.display, fill=params.fill)
    contrast = DISPLAYS[params.display][4]
    return replace(named, peak_luminance=params.display_max, black_level=params.display_max / contrast,
                   name=f"{params.display} (white {params.display_max:g} cd/m^2, the tone mapping's)")


def viewing_line(params: ToneMapping, width: int, height: int, aqm_size: int) -> str:
    """What the AQM assumes of the viewer, in one line: the display, its distance, and the pixels
    per degree of a frame and of the AQM's image (§6): ``loom render`` prints it, the report shows it."""
    view = viewing_for(params)
    return aqm_geometry(view, (height, width), aqm_size).describe(view)


def displayed_difference(rgb_a: np.ndarray, rgb_b: np.ndarray, adaptation: float, *,
                         params: ToneMapping = ToneMapping(), aqm_size: int = AQM_SIZE,
                         flow: np.ndarray | None = None) -> AQMResult:
    """d_AQM and M_AQM of two linear renderings of one frame as the viewer sees them; ``flow`` the
    image velocity of camera motion in deg/s (:func:`camera_flow`), None for a still camera."""
    view = viewing_for(params)
    return aqm(display_values(rgb_a, adaptation, params), display_values(rgb_b, adaptation, params),
               viewing=view, aqm_size=aqm_size, names=("I1", "I2"), motion=None if flow is None else Motion(flow))


def lens(cam: Camera) -> Lens:
    """The camera's lens as the AQM's warping takes it: its field of view, or its orthographic view."""
    return Ortho(cam.definition.ymag) if cam.definition.orthographic else cam.definition.yfov


def camera_flow(scene: Scene, frame: int, width: int, height: int,
                params: ToneMapping = ToneMapping()) -> np.ndarray | None:
    """Image velocity (H, W, 2) in deg/s that the camera's own motion gives frame ``frame`` (§6: pixel
    flow by 3-D warping of the neighbouring frames' cameras; moving objects are assumed tracked by
    the eye), from a depth image of pixel-centre rays cast with Embree. None when the camera does
    not move around this frame (the AQM then takes the eye as still)."""
    state = scene.pose_frame(frame)
    cam = state.camera
    neighbours = {}
    for name, g in (("previous", frame - 1), ("following", frame + 1)):
        if 1 <= g <= scene.timeline.frames:
            other = scene.pose_frame(g).camera
            neighbours[name] = (other.world_to_camera, lens(other))
    here, yfov = cam.world_to_camera, lens(cam)
    if not neighbours or all(np.allclose(m, here, rtol=0, atol=1e-9) and fov == yfov for m, fov in neighbours.values()):
        return None
    ortho = isinstance(yfov, Ortho)
    f = 0.5 * height / (yfov.ymag if ortho else np.tan(0.5 * yfov))
    x = (np.arange(width) + 0.5 - 0.5 * width) / f
    y = -(np.arange(height) + 0.5 - 0.5 * height) / f
    local = np.stack(np.broadcast_arrays(x[None, :], y[:, None], -np.ones((height, width))), axis=-1).reshape(-1, 3)
    rot = cam.to_world[:3, :3] / np.linalg.norm(cam.to_world[:3, :3], axis=0)
    if ortho:  # parallel rays from the image's points, depth their length
        origins = cam.position + (local * [1.0, 1.0, 0.0]) @ rot.T
        dirs = np.broadcast_to(-rot[:, 2], origins.shape)
    else:
        dirs = local @ rot.T
        origins = np.broadcast_to(cam.position, dirs.shape)
    lengths = np.linalg.norm(dirs, axis=1, keepdims=True)
    tri, _, _, t = caster_for(state).intersect(np.ascontiguousarray(origins, np.float32),
                                                np.ascontiguousarray(dirs / lengths, np.float32))
    depth = np.where(tri >= 0, t.astype(np.float64) / lengths[:, 0], np.inf).reshape(height, width)
    return image_velocity(np.maximum(depth, 1e-6), here, yfov=yfov, fps=scene.timeline.fps,
                          ppd=viewing_for(params).frame_ppd((height, width)), **neighbours)
