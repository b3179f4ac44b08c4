"""ROOM: the paper's main test scene (§6, Figs. 1, 3, 7), about 5,300 elements, 135 frames.

Layout (metres, y up): a 6 x 3 x 5 box, x in [0, 6], z in [0, 5]. Red wall at x = 0, blue wall at
z = 5 (behind the camera), the floor, ceiling, back wall (z = 0) and right wall (x = 6) white-ish.
In the back-left corner a niche (x < 1.5, z < 1.6, under a soffit at 2.2 m) opens towards +z; a
full-height partition at x = 1.5 hides it from every light, so it is lit only indirectly.
A polished metal sphere stands on the floor under the flight path (specular paths).

Lights and motion, in three 45-frame segments:
- ``aircraft``: a white fuselage-and-wings body flying one and a half laps of a 1.25 m circle
  round the middle of the room at 1.35 m, banking into the turn, about 10 cm a frame. A spot
  light (10 W/sr, 40 deg cone) travels 0.38 m under it, pointing up, and lights only its
  underside; the light the underside reflects makes a highlight on the floor below that moves
  about 1.5 m in 15 frames, so collecting +-15 frames of photons without regard to the change
  washes it out (Fig. 3b) while adaptive collection keeps it (Fig. 3c). The cone sees only steep
  upward directions, so it never lights the niche.
- ``corner_spot``: a fixed ceiling spot (150 W/sr, 14 deg cone) aimed into the back-right corner,
  narrow enough to light mainly the torus there. The saturated green
  ``torus`` stands there, strongly lit, for frames 1-45 (green colour bleeding on the white walls
  and floor, Fig. 1), moves out of the cone during frames 46-90 (the bleeding fades), and rests in
  the room's middle for frames 91-135 while the aircraft finishes its flight.
The camera is static high at the front, looking down on the floor highlight, the torus corner and the niche.
"""
from __future__ import annotations

import math

import numpy as np

from pipeline.scene.builtin import shapes
from pipeline.scene.builtin.gltf_builder import GltfBuilder
from pipeline.scene.timeline import Timeline

ELEMENT_SIZE = 0.4
TIMELINE = Timeline(fps=30, frames=135)
WIDTH, HEIGHT, DEPTH = 6.0, 3.0, 5.0
NICHE_X, NICHE_Z, SOFFIT_Y = 1.5, 1.6, 2.2


def _add_shell(b: GltfBuilder) -> None:
    """Floor, ceiling and walls facing into the room, and the niche (partition, soffit, fascia)."""
    white = b.add_material("wall_white", (0.72, 0.72, 0.70))
    ceiling_white = b.add_material("ceiling_white", (0.78, 0.78, 0.78))
    floor_grey = b.add_material("floor_grey", (0.55, 0.52, 0.48))
    red = b.add_material("wall_red", (0.75, 0.12, 0.10))
    blue = b.add_material("wall_blue", (0.12, 0.20, 0.70))
    materials = {"floor": floor_grey, "ceiling": ceiling_white, "wall_left": red, "wall_right": white,
                 "wall_back": white, "wall_front": blue}
    shell = shapes.room_shell(WIDTH, HEIGHT, DEPTH)
    walls = [(name, shell[name], material) for name, material in materials.items()]
    # The niche: a partition, the soffit closing it at 2.2 m, a fascia above its opening. Single
    # quads suffice: surfaces reflect on both faces.
    niche = shapes.merge([
        shapes.quad((NICHE_X, 0, 0), (0, 0, NICHE_Z), (0, HEIGHT, 0)),                    # faces +x
        shapes.quad((0, SOFFIT_Y, 0), (NICHE_X, 0, 0), (0, 0, NICHE_Z)),                   # faces -y
        shapes.quad((0, SOFFIT_Y, NICHE_Z), (NICHE_X, 0, 0), (0, HEIGHT - SOFFIT_Y, 0)),   # faces +z
    ])
    walls.append(("niche", niche, white))
    for name, (positions, indices), material in walls:
        b.add_node(name, b.add_mesh(name, positions, indices, material))


FLIGHT_CENTRE, FLIGHT_RADIUS, FLIGHT_HEIGHT, FLIGHT_LAPS = (3.55, 2.6), 1.25, 1.35, 1.5
FLIGHT_KEY_STEP = 5  # frames between the flight's keys (a 27-gon per 1.5 laps, close to the circle)


def _add_aircraft(b: GltfBuilder) -> None:
    """The aircraft with its upward spot light as a child, circling the room's middle at 1.35 m."""
    body = b.add_material("aircraft_white", (0.8, 0.8, 0.8))
    mesh = shapes.merge([
        shapes.box((1.4, 0.26, 0.28)),                              # fuselage along x
        shapes.box((0.5, 0.05, 1.8), (0.05, -0.05, 0.0)),           # wings along z
        shapes.box((0.25, 0.04, 0.7), (-0.6, 0.0, 0.0)),           # tailplane
        shapes.box((0.25, 0.3, 0.04), (-0.6, 0.25, 0.0)),          # fin
    ])
    spot = b.add_spot_light("aircraft_spot", (1.0, 0.95, 0.85), 10.0,
                            inner_cone_angle=math.radians(28), outer_cone_angle=math.radians(40))
    up = shapes.axis_angle((1, 0, 0), math.pi / 2)  # the light's -Z turned to +Y
    light_node = b.add_node("aircraft_spot", translation=(0.05, -0.38, 0.0), rotation=up, light=spot)
    mesh_node = b.add_node("aircraft_body", b.add_mesh("aircraft", *mesh, material=body))
    aircraft = b.add_node("aircraft", children=[mesh_node, light_node])
    keys = np.arange(1, TIMELINE.frames + 1, FLIGHT_KEY_STEP)
    if keys[-1] != TIMELINE.frames:
        keys = np.append(keys, TIMELINE.frames)
    times = [TIMELINE.time(f) for f in keys]
    # Counter-clockwise seen from above: angle theta round the centre, position (cx + r cos, cz - r sin)
    theta = 2.0 * math.pi * FLIGHT_LAPS * (keys - 1) / (TIMELINE.frames - 1)
    cx, cz = FLIGHT_CENTRE
    path = np.stack([cx + FLIGHT_RADIUS * np.cos(theta), np.full(len(keys), FLIGHT_HEIGHT),
                     cz - FLIGHT_RADIUS * np.sin(theta)], axis=1)
    b.add_animation("aircraft_flight", aircraft, "translation", times, path)
    # Nose (+x) along the tangent: a turn about +y by theta + 90 degrees; 12 degrees of bank inward.
    bank = shapes.axis_angle((1, 0, 0), math.radians(12.0))
    heading = [shapes.multiply_quaternions(shapes.axis_angle((0, 1, 0), t + math.pi / 2), bank) for t in theta]
    b.add_animation("aircraft_flight", aircraft, "rotation", times, _continuous(heading))


def _continuous(quaternions: list) -> np.ndarray:
    """Flip signs so consecutive keys lie on the same hemisphere (slerp takes the short way anyway,
    but CUBICSPLINE or other readers may not)."""
    out = np.array(quaternions, dtype=np.float64)
    for i in range(1, len(out)):
        if np.dot(out[i], out[i - 1]) < 0:
            out[i] = -out[i]
    return out


def _add_torus_corner(b: GltfBuilder) -> None:
    """The green torus, lit in the back-right corner by a fixed spot, leaving it from frame 46."""
    corner_target = np.array([5.3, 0.6, 0.7])
    eye = np.array([4.6, 2.9, 1.2])
    spot = b.add_spot_light("corner_spot", (1.0, 0.97, 0.9), 150.0,
                            inner_cone_angle=math.radians(9), outer_cone_angle=math.radians(14))
    b.add_node("corner_spot", translation=eye, rotation=shapes.look_at(eye, corner_target), light=spot)
    green = b.add_material("torus_green", (0.05, 0.8, 0.1))
    ring = shapes.torus(0.42, 0.14, 32, 12)
    torus = b.add_node("torus", b.add_mesh("torus", *ring, material=green,
                                           normals=shapes.torus_normals(ring[0], 0.42)))
    times = [TIMELINE.time(f) for f in (1, 45, 90, 135)]
    positions = [[5.3, 0.57, 0.7], [5.3, 0.57, 0.7], [3.6, 0.57, 2.1], [3.6, 0.57, 2.1]]
    tilt = shapes.axis_angle((1, 0, 0), math.pi / 2)  # ring stands vertical, its hole along z
    headings = np.radians([-45.0, -45.0, 30.0, 30.0])  # first facing the corner's diagonal
    rotations = [shapes.multiply_quaternions(shapes.axis_angle((0, 1, 0), h), tilt) for h in headings]
    b.add_animation("torus_leaves_corner", torus, "translation", times, positions)
    b.add_animation("torus_leaves_corner", torus, "rotation", times, rotations)


def build() -> GltfBuilder:
    """The ROOM scene (see the module docstring)."""
    b = GltfBuilder("room")
    _add_shell(b)
    metal = b.add_material("polished_metal", (0.9, 0.9, 0.92), metallic=1.0, roughness=0.05)
    ball = shapes.uv_sphere(0.35, 10, 20)
    smooth = shapes.sphere_normals(ball[0])  # vertex normals: shaded smooth, not faceted
    b.add_node("metal_sphere", b.add_mesh("metal_sphere", *ball, material=metal, normals=smooth),
               translation=(2.0, 0.35, 3.2))
    _add_aircraft(b)
    _add_torus_corner(b)
    eye, target = (3.0, 2.9, 4.9), (3.2, 0.0, 1.5)
    camera = b.add_camera("camera", yfov=math.radians(70), znear=0.05, zfar=30.0)
    b.add_node("camera", camera=camera, translation=eye, rotation=shapes.look_at(eye, target))
    b.set_scene_extras({"photonloom": {"element_size": ELEMENT_SIZE, "fps": TIMELINE.fps,
                                       "frames": TIMELINE.frames}})
    return b
