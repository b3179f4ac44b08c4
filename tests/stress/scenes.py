"""Scenes of the numerical stress suite, written with the real glTF builder."""
from __future__ import annotations

import numpy as np

from pipeline.scene.builtin.gltf_builder import GltfBuilder
from pipeline.scene.builtin.shapes import look_at


def inward_quads(half: float = 1.0) -> list[np.ndarray]:
    """The six faces of the cube [-half, half]^3 as (4, 3) quads wound counter-clockwise seen from
    inside (front faces look into the box)."""
    quads = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            u, v = [a for a in range(3) if a != axis]
            q = np.zeros((4, 3))
            q[:, axis] = sign * half
            q[:, u] = [-half, half, half, -half]
            q[:, v] = [-half, -half, half, half]
            normal = np.cross(q[1] - q[0], q[2] - q[0])
            if normal[axis] * sign > 0:  # facing out: reverse the winding
                q = q[::-1].copy()
            quads.append(q)
    return quads


QUAD_FACES = np.array([0, 1, 2, 0, 2, 3])


def furnace_box(path, *, rho: float, radiance: float, element_size: float = 0.5):
    """A closed 2 x 2 x 2 box whose six walls are diffuse (albedo ``rho``) and emit ``radiance``
    from their inner faces, a camera at its centre: every point inside sees radiance L / (1 - rho)."""
    b = GltfBuilder()
    wall = b.add_material("wall", (rho, rho, rho), emissive=(1.0, 1.0, 1.0), emissive_strength=radiance)
    for i, q in enumerate(inward_quads()):
        b.add_node(f"wall{i}", b.add_mesh(f"wall{i}", q, QUAD_FACES, material=wall))
    eye = np.zeros(3)
    b.add_node("cam", camera=b.add_camera("cam", 1.2, 0.01), translation=tuple(eye),
               rotation=look_at(eye, (0.3, -0.4, -1.0), (0, 1, 0)))
    b.set_scene_extras({"photonloom": {"element_size": element_size, "fps": 30}})
    return b.write(path)


def lit_room(path, *, scale: float = 1.0, dim_ratio: float | None = None, bright: bool = True,
             frames: int = 1, extra=None, element_size: float = 0.5):
    """A closed 4 x 4 x 4 room with coloured walls, a box on the floor, a point light, a spot and an
    emissive ceiling panel, every light's power times ``scale``; the camera inside looks at the
    box. ``dim_ratio`` adds a closed 2 x 2 x 2 room of its own outside the first (centred at
    x = 5) with a point light ``dim_ratio`` times dimmer than the first; ``bright`` False leaves out
    the first room's lights. ``extra(builder)`` adds geometry. With ``frames`` > 1 the point light moves."""
    b = GltfBuilder()
    colours = [(0.7, 0.2, 0.2), (0.2, 0.7, 0.2), (0.7, 0.7, 0.7), (0.6, 0.6, 0.6), (0.7, 0.7, 0.7),
               (0.5, 0.5, 0.8)]
    for i, q in enumerate(inward_quads(2.0)):
        mat = b.add_material(f"wall{i}", colours[i])
        b.add_node(f"wall{i}", b.add_mesh(f"wall{i}", q, QUAD_FACES, material=mat))
    grey = b.add_material("box", (0.6, 0.5, 0.4))
    box = [q * 0.5 + [0.5, -1.5, -0.5] for q in inward_quads(1.0)]
    faces = np.concatenate([QUAD_FACES + 4 * i for i in range(6)])
    b.add_node("box", b.add_mesh("box", np.concatenate(box), faces, material=grey))
    if bright:
        glow = b.add_material("panel", (0.8, 0.8, 0.8), emissive=(1.0, 0.9, 0.8),
                              emissive_strength=2.0 * scale)
        panel = np.array([[-0.4, 1.99, -0.4], [0.4, 1.99, -0.4], [0.4, 1.99, 0.4], [-0.4, 1.99, 0.4]])
        b.add_node("panel", b.add_mesh("panel", panel, QUAD_FACES, material=glow))  # faces down
        lamp = b.add_node("lamp", light=b.add_point_light("lamp", (1.0, 0.9, 0.8), 3.0 * scale),
                          translation=(-1.0, 1.0, 0.5))
        if frames > 1:
            b.add_animation("lamp", lamp, "translation", [0.0, (frames - 1) / 30.0],
                            [(-1.0, 1.0, 0.5), (-0.6, 1.0, 0.2)])
        spot = b.add_spot_light("spot", (0.9, 0.9, 1.0), 8.0 * scale, inner_cone_angle=0.3,
                                outer_cone_angle=0.6)
        b.add_node("spot", light=spot, translation=(1.5, 1.5, 1.5),
                   rotation=look_at((1.5, 1.5, 1.5), (0.5, -1.5, -0.5)))
    if dim_ratio is not None:
        white = b.add_material("far", (0.7, 0.7, 0.7))
        quads = [q + [5.0, 0.0, 0.0] for q in inward_quads(1.0)]
        faces = np.concatenate([QUAD_FACES + 4 * i for i in range(6)])
        b.add_node("far", b.add_mesh("far", np.concatenate(quads), faces, material=white))
        b.add_node("dim", light=b.add_point_light("dim", (1.0, 1.0, 1.0), 3.0 * scale / dim_ratio),
                   translation=(5.3, 0.2, -0.1))
    if extra is not None:
        extra(b)
    eye = np.array([-1.2, 0.2, 1.8])
    b.add_node("cam", camera=b.add_camera("cam", 1.1, 0.01), translation=tuple(eye),
               rotation=look_at(eye, (0.3, -1.2, -0.8), (0, 1, 0)))
    b.set_scene_extras({"photonloom": {"element_size": element_size, "fps": 30}})
    return b.write(path)
