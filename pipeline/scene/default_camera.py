"""The camera a file without one is rendered with (``--camera auto``): the whole animation in view.

Decision: the camera looks at the centre of the world-space bounding box of every
mesh over every frame of the timeline, from azimuth ``AZIMUTH`` (degrees from +Z, glTF's front,
towards +X) and elevation ``ELEVATION`` above the horizon (front-right and a little above, the
three-quarter view of a product shot), with vertical field of view ``YFOV_DEG``. It stands back
just far enough that the box's eight corners, grown by ``MARGIN``, fall inside a square of that
field of view, so any frame at least as wide as it is tall shows everything that ever moves; a
portrait frame (narrower) may crop the sides. It does not move: a fixed camera shows the
animation itself and lets one photon set serve frames whose geometry stands still.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .camera import AUTO, Camera, CameraDef, Framing
from .sky import UP, direction_from

if TYPE_CHECKING:
    from .scene import Scene
    from .timeline import Timeline

AZIMUTH = 30.0
ELEVATION = 20.0
YFOV_DEG = 40.0
MARGIN = 1.05


def sample_frames(timeline: "Timeline", n: int) -> list[int]:
    """At most ``n`` frames of ``timeline`` spread evenly from its first to its last."""
    return sorted({round(x) for x in np.linspace(timeline.first, timeline.last, min(timeline.frames, n))})


def animation_bounds(scene: "Scene", frames: list[int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) world bounds of every instance's posed vertices over ``frames`` (default: every
    frame of the timeline); each distinct instance matrix of a rigid instance is applied once
    (standing instances cost one transform), a skinned or morphed one is posed at every frame."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    seen: set[tuple[int, bytes]] = set()
    for frame in scene.timeline.all_frames() if frames is None else frames:
        t = scene.timeline.time(frame)
        world = scene.world_matrices(t)
        for inst in scene.instances:
            if inst.deformation is not None:
                v = scene.deformed_vertices(inst, world, t, normals=False)[0]
            else:
                m = world[inst.node]
                mark = (inst.index, m.tobytes())
                if mark in seen:
                    continue
                seen.add(mark)
                v = inst.vertices @ m[:3, :3].T + m[:3, 3]
            lo, hi = np.minimum(lo, v.min(0)), np.maximum(hi, v.max(0))
    return lo, hi


def framing_camera(lo: np.ndarray, hi: np.ndarray) -> Camera:
    """A static camera from AZIMUTH, ELEVATION with YFOV_DEG that frames the box [lo, hi]."""
    target = (lo + hi) / 2.0
    back = direction_from(AZIMUTH, ELEVATION)  # from the target towards the camera: its +Z
    right = np.cross(UP, back)
    right /= np.linalg.norm(right)
    up = np.cross(back, right)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    rel = (corners - target) * MARGIN
    x, y, z = rel @ right, rel @ up, rel @ back
    tan_half = np.tan(np.radians(YFOV_DEG) / 2.0)
    diagonal = max(float(np.linalg.norm(hi - lo)), 1e-6)
    # depth of a corner is distance - z; it must be at least max(|x|, |y|) / tan(yfov / 2)
    distance = float(np.max(z + np.maximum(np.abs(x), np.abs(y)) / tan_half))
    distance = max(distance, float(z.max()) + 1e-3 * diagonal)
    to_world = np.eye(4)
    to_world[:3, 0], to_world[:3, 1], to_world[:3, 2] = right, up, back
    to_world[:3, 3] = target + back * distance
    znear = max(1e-4 * diagonal, 0.5 * (distance - float(z.max())))
    return Camera(CameraDef(AUTO, float(np.radians(YFOV_DEG)), znear, None, None), -1, to_world)


def describe_framing(framing: Framing) -> str:
    """One line for notices and ``loom info``: where the auto camera stands and what it frames."""
    p, c = framing.camera.position, (framing.lo + framing.hi) / 2.0
    return (f"auto camera from azimuth {AZIMUTH:g} deg, elevation {ELEVATION:g} deg, yfov {YFOV_DEG:g} deg "
            f"at {_xyz(p)} looking at {_xyz(c)}, framing the bounds {_xyz(framing.lo)}-{_xyz(framing.hi)} "
            "of the whole animation")


def frame_animation(scene: "Scene") -> Framing:
    """The auto camera of ``scene``: it frames the bounds of the whole animation."""
    lo, hi = animation_bounds(scene)
    return Framing(framing_camera(lo, hi), lo, hi)


def _xyz(v) -> str:
    return "(" + ", ".join(f"{c:.3g}" for c in v) + ")"
