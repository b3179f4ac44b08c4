"""glTF files as sample collections ship them: no camera and no light (written with the real builder)."""
from __future__ import annotations

import numpy as np

from pipeline.scene.builtin.gltf_builder import GltfBuilder
from pipeline.scene.builtin.shapes import axis_angle, box, merge, quad

INNER = (0.8, 0.1, 0.1)  # the moving box's albedo: it tells its pixels apart in the albedo layer
OUTER = (0.6, 0.6, 0.6)
FRAMES = 16
SLIDE = 1.2  # the inner box moves this far along +x over the animation


def box_in_box(path):
    """Two boxes like the "box in a box" sample: an outer box open at the front and top (floor, back
    and side walls, 3 x 1.5 x 3) and a 0.6 cube inside that slides SLIDE along +x while turning a
    quarter turn about y, over FRAMES frames at 30 fps; no camera, no light."""
    b = GltfBuilder()
    outer = b.add_material("outer", OUTER)
    inner = b.add_material("inner", INNER)
    walls = merge([quad((-1.5, 0, -1.5), (0, 0, 3), (3, 0, 0)),      # floor, facing up
                   quad((-1.5, 0, -1.5), (3, 0, 0), (0, 1.5, 0)),    # back wall, facing +z
                   quad((-1.5, 0, -1.5), (0, 1.5, 0), (0, 0, 3)),    # left wall, facing +x
                   quad((1.5, 0, -1.5), (0, 0, 3), (0, 1.5, 0))])    # right wall, facing -x
    b.add_node("outer_box", b.add_mesh("outer_box", walls[0], walls[1], material=outer))
    cube = box((0.6, 0.6, 0.6), (0.0, 0.3, 0.0))
    node = b.add_node("inner_box", b.add_mesh("inner_box", cube[0], cube[1], material=inner),
                      translation=(-SLIDE / 2, 0.0, 0.0))
    end = (FRAMES - 1) / 30.0
    b.add_animation("move", node, "translation", [0.0, end], [[-SLIDE / 2, 0, 0], [SLIDE / 2, 0, 0]])
    b.add_animation("move", node, "rotation", [0.0, end], [[0, 0, 0, 1], axis_angle((0, 1, 0), np.pi / 2)])
    return b.write(path)
