"""Scenes for the eye-adaptation tests, written with the real glTF builder: a BoxAnimated-like
blue box sliding over a grey ground under a point light, optionally with a second light that is
switched on mid-animation (a spot light that turns from the empty sky above onto the scene)."""
from __future__ import annotations

import numpy as np

from pipeline.scene.builtin.gltf_builder import GltfBuilder
from pipeline.scene.builtin.shapes import box, look_at

BLUE = (0.30, 0.53, 0.80)  # BoxAnimated's base colour
GREY = (0.5, 0.5, 0.5)
UP_FACES = np.array([0, 2, 1, 0, 3, 2])
FPS = 24


def ground(half: float) -> np.ndarray:
    return np.array([[-half, 0, -half], [half, 0, -half], [half, 0, half], [-half, 0, half]], float)


def box_scene(path, *, frames: int = 24, switch_at: int | None = None, element_size: float = 0.5):
    """A 1 m blue box sliding 2 m along x over a 12 m grey ground, lit by a point light in front
    of it (its shadow falls away from the camera), seen from a fixed camera; ``frames`` at 24 fps.
    ``switch_at``: from that frame (1-based) on, a second, stronger light shines on the scene: a
    spot above it that until then points up, at nothing (glTF cannot animate an intensity)."""
    b = GltfBuilder()
    grey = b.add_material("ground", GREY)
    b.add_node("ground", b.add_mesh("ground", ground(6.0), UP_FACES, material=grey))
    blue = b.add_material("box", BLUE)
    pos, idx = box((1.0, 1.0, 1.0), (0.0, 0.5, 0.0))
    node = b.add_node("box", b.add_mesh("box", pos, idx.reshape(-1), material=blue), translation=(-1.0, 0.0, 0.0))
    end = (frames - 1) / FPS
    b.add_animation("slide", node, "translation", [0.0, end], [[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    b.add_node("lamp", light=b.add_point_light("lamp", (1.0, 1.0, 1.0), 40.0), translation=(0.0, 4.0, 3.0))
    if switch_at is not None:
        t = (switch_at - 1) / FPS
        spot = b.add_spot_light("switched", (1.0, 1.0, 1.0), 400.0, inner_cone_angle=0.6, outer_cone_angle=0.9)
        top = (0.0, 5.0, 2.0)
        up, down = look_at(top, (0.0, 10.0, 2.0), (0.0, 0.0, -1.0)), look_at(top, (0.0, 0.0, 0.0))
        lamp = b.add_node("switched", light=spot, translation=top, rotation=up)
        b.add_animation("switch", lamp, "rotation", [0.0, t], [up, down], interpolation="STEP")
    eye = (0.0, 3.0, 7.0)
    b.add_node("cam", camera=b.add_camera("cam", 0.7, 0.05), translation=eye, rotation=look_at(eye, (0, 0.3, 0)))
    b.set_scene_extras({"photonloom": {"element_size": element_size, "fps": FPS, "frames": frames}})
    return b.write(path)
