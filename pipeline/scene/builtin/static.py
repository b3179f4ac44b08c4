"""STATIC: a small furnished room where only the camera moves, 30 frames, about 1,300 elements.

Layout (metres, y up): a 4 x 2.5 x 4 room, x and z in [0, 4], with a yellow wall at x = 0 and the
rest off-white; on the floor a table-like block, a cube and a polished metal sphere (a specular
path). Lights: a point lamp under the ceiling and a spot on the back wall aimed at the cube; no
light and no object is animated.

The camera orbits a quarter turn around the room's centre over the 30 frames. Every frame has the
same geometry and lights, so later stages must recognise camera-only motion and reuse one
frame's photons for all of them (the state keys of all frames are equal).
"""
from __future__ import annotations

import math

import numpy as np

from pipeline.scene.builtin import shapes
from pipeline.scene.builtin.gltf_builder import GltfBuilder
from pipeline.scene.timeline import Timeline

ELEMENT_SIZE = 0.6
TIMELINE = Timeline(fps=30, frames=30)
SIZE, HEIGHT = 4.0, 2.5


def build() -> GltfBuilder:
    """The STATIC scene (see the module docstring)."""
    b = GltfBuilder("static")
    white = b.add_material("off_white", (0.7, 0.7, 0.66))
    yellow = b.add_material("yellow", (0.75, 0.65, 0.15))
    wood = b.add_material("wood", (0.5, 0.33, 0.18))
    blue = b.add_material("blue", (0.12, 0.2, 0.65))
    metal = b.add_material("polished_metal", (0.9, 0.9, 0.9), metallic=1.0, roughness=0.05)
    for name, mesh in shapes.room_shell(SIZE, HEIGHT, SIZE).items():
        b.add_node(name, b.add_mesh(name, *mesh, material=yellow if name == "wall_left" else white))
    b.add_node("table", b.add_mesh("table", *shapes.box((1.2, 0.7, 0.8), (0, 0.35, 0)), material=wood),
               translation=(1.4, 0.0, 1.5))
    b.add_node("cube", b.add_mesh("cube", *shapes.box((0.5, 0.5, 0.5), (0, 0.25, 0)), material=blue),
               translation=(2.8, 0.0, 1.2), rotation=shapes.axis_angle((0, 1, 0), math.radians(30)))
    ball = shapes.uv_sphere(0.3, 8, 16)
    smooth = shapes.sphere_normals(ball[0])  # vertex normals: shaded smooth, not faceted
    b.add_node("metal_sphere", b.add_mesh("metal_sphere", *ball, material=metal, normals=smooth),
               translation=(2.6, 0.3, 2.6))

    lamp = b.add_point_light("ceiling_lamp", (1.0, 0.9, 0.75), 8.0)
    b.add_node("ceiling_lamp", translation=(2.0, 2.3, 2.0), light=lamp)
    spot = b.add_spot_light("wall_spot", (0.9, 0.95, 1.0), 15.0,
                            inner_cone_angle=math.radians(15), outer_cone_angle=math.radians(25))
    eye = (3.5, 2.2, 0.2)
    b.add_node("wall_spot", translation=eye, rotation=shapes.look_at(eye, (2.8, 0.25, 1.2)), light=spot)

    camera = b.add_camera("camera", yfov=math.radians(55), znear=0.05, zfar=20.0)
    centre = np.array([2.0, 0.6, 2.0])
    angles = np.radians(np.linspace(0.0, 90.0, 4))
    eyes = [centre + [1.7 * math.sin(a), 1.0, 1.7 * math.cos(a)] for a in angles]
    node = b.add_node("camera", camera=camera, translation=eyes[0], rotation=shapes.look_at(eyes[0], centre))
    keys = np.linspace(0.0, TIMELINE.duration, len(eyes))
    b.add_animation("camera_orbit", node, "translation", keys, eyes)
    b.add_animation("camera_orbit", node, "rotation", keys, [shapes.look_at(e, centre) for e in eyes])
    b.set_scene_extras({"photonloom": {"element_size": ELEMENT_SIZE, "fps": TIMELINE.fps,
                                       "frames": TIMELINE.frames}})
    return b
