"""Small glTF scenes for the render tests, written with the real builder."""
from __future__ import annotations

import numpy as np

from pipeline.scene.builtin.gltf_builder import GltfBuilder
from pipeline.scene.builtin.shapes import look_at

UP_FACES = np.array([0, 2, 1, 0, 3, 2])  # CCW seen from +y: the front face looks up
LAMP = np.array([0.5, 2.0, 0.3])
EYE = np.array([0.0, 3.0, 0.0])  # looking straight down at the plane y = 0


def quad_y(half: float, y: float = 0.0) -> np.ndarray:
    return np.array([[-half, y, -half], [half, y, -half], [half, y, half], [-half, y, half]], float)


def camera(b: GltfBuilder, eye, target, yfov: float = 0.8, up=(0.0, 0.0, -1.0)) -> None:
    b.add_node("cam", camera=b.add_camera("cam", yfov, 0.05),
               translation=tuple(eye), rotation=look_at(eye, target, up))


def plane_scene(path, *, light: str = "point", albedo=(0.5, 0.6, 0.7), occluder: bool = False,
                frames: int = 1, roughness: float | None = None):
    """A 20 x 20 diffuse plane at y = 0 under one light, seen from above; optionally an opaque
    0.6 x 0.6 square at y = 1 under the lamp, a few frames of a slowly moving camera, or a glossy
    metal plane of the given roughness."""
    b = GltfBuilder()
    if roughness is None:
        mat = b.add_material("plane", albedo)
    else:
        mat = b.add_material("plane", albedo, metallic=1.0, roughness=roughness)
    b.add_node("plane", b.add_mesh("plane", quad_y(10.0), UP_FACES, material=mat))
    if light == "point":
        b.add_node("lamp", light=b.add_point_light("lamp", (1.0, 0.9, 0.8), 10.0), translation=tuple(LAMP))
    elif light == "spot":
        spot = b.add_spot_light("lamp", (1.0, 1.0, 1.0), 20.0, inner_cone_angle=0.3, outer_cone_angle=0.7)
        b.add_node("lamp", light=spot, translation=tuple(LAMP), rotation=look_at(LAMP, (0.5, 0.0, 0.3)))
    else:  # directional, 30 degrees from the vertical
        d = np.array([np.sin(0.5), -np.cos(0.5), 0.0])
        b.add_node("lamp", light=b.add_directional_light("lamp", (1.0, 1.0, 1.0), 3.0),
                   rotation=look_at((0, 0, 0), d))
    if occluder:
        grey = b.add_material("occluder", (0.5, 0.5, 0.5))
        sq = quad_y(0.3, 1.0) + [0.5, 0.0, 0.3]
        b.add_node("occluder", b.add_mesh("occluder", sq, UP_FACES, material=grey))
    cam = b.add_camera("cam", 0.8, 0.05)
    node = b.add_node("cam", camera=cam, translation=tuple(EYE), rotation=look_at(EYE, (0, 0, 0), (0, 0, -1)))
    if frames > 1:
        times = [0.0, (frames - 1) / 30.0]
        b.add_animation("pan", node, "translation", times, [EYE, EYE + [0.2, 0.0, 0.0]])
    b.set_scene_extras({"photonloom": {"element_size": 2.0, "fps": 30}})
    return b.write(path)


def mirror_scene(path):
    """A mirror (reflectance 0.8, 0.9, 0.7) in the plane z = 0 facing +z, an emitter behind the
    camera facing the mirror (radiance 2, 1, 0.5), and a dim lamp so the scene has a light."""
    b = GltfBuilder()
    mirror = b.add_material("mirror", (0.8, 0.9, 0.7), metallic=1.0, roughness=0.0)
    quad = np.array([[-5, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0]], float)
    b.add_node("mirror", b.add_mesh("mirror", quad, np.array([0, 1, 2, 0, 2, 3]), material=mirror))
    glow = b.add_material("glow", (0.0, 0.0, 0.0), emissive=(1.0, 0.5, 0.25), emissive_strength=2.0)
    back = quad * [2, 2, 1] + [0, 0, 6]
    b.add_node("emitter", b.add_mesh("emitter", back, np.array([0, 2, 1, 0, 3, 2]), material=glow))
    camera(b, (0.0, 0.0, 3.0), (0.0, 0.0, 0.0), yfov=0.5, up=(0, 1, 0))
    b.set_scene_extras({"photonloom": {"element_size": 5.0}})
    return b.write(path)


def area_scene(path, half: float = 0.5, height: float = 1.0, radiance: float = 3.0, eye=(0.0, 0.5, 0.0)):
    """A square emitter (side 2 x half, facing down) at ``height`` over a grey plane, seen from
    ``eye`` looking straight down through a narrow field of view."""
    b = GltfBuilder()
    grey = b.add_material("plane", (0.5, 0.5, 0.5))
    b.add_node("plane", b.add_mesh("plane", quad_y(10.0), UP_FACES, material=grey))
    glow = b.add_material("glow", (0.0, 0.0, 0.0), emissive=(1.0, 1.0, 1.0), emissive_strength=radiance)
    b.add_node("panel", b.add_mesh("panel", quad_y(half, height), np.array([0, 1, 2, 0, 2, 3]), material=glow))
    camera(b, eye, (eye[0], 0.0, eye[2]), yfov=0.05)
    b.set_scene_extras({"photonloom": {"element_size": 2.0}})
    return b.write(path)
