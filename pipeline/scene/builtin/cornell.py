"""CORNELL: a small Cornell box with one moving block, a few hundred elements, 30 frames, for fast tests.

Layout (metres, y up): a 1 m cube, x, y, z in [0, 1], open at z = 1 where the camera looks in
down -z. Red wall at x = 0, green wall at x = 1, white floor, ceiling and back wall. A 0.3 m
square emissive panel just under the ceiling's centre, facing down, is the only light (an area
light, exercising emissive materials). A tall white block stands still; a short white block slides
across the floor from left to right over the 30 frames (LINEAR), so the red and green colour
bleeding on it and its shadow change from frame to frame.
"""
from __future__ import annotations

import math

from pipeline.scene.builtin import shapes
from pipeline.scene.builtin.gltf_builder import GltfBuilder
from pipeline.scene.timeline import Timeline

ELEMENT_SIZE = 0.4
TIMELINE = Timeline(fps=30, frames=30)
LIGHT_SIZE = 0.3
LIGHT_RADIANCE = 20.0


def build() -> GltfBuilder:
    """The CORNELL scene (see the module docstring)."""
    b = GltfBuilder("cornell")
    white = b.add_material("white", (0.73, 0.73, 0.73))
    red = b.add_material("red", (0.63, 0.06, 0.05))
    green = b.add_material("green", (0.14, 0.45, 0.09))
    lamp = b.add_material("ceiling_lamp", (0.78, 0.78, 0.78), emissive=(1.0, 0.9, 0.75),
                          emissive_strength=LIGHT_RADIANCE)
    shell = shapes.room_shell(1.0, 1.0, 1.0)
    for name, material in (("floor", white), ("ceiling", white), ("wall_back", white), ("wall_left", red),
                           ("wall_right", green)):  # no front wall: the camera looks in
        b.add_node(name, b.add_mesh(name, *shell[name], material=material))
    corner = 0.5 - LIGHT_SIZE / 2
    panel = shapes.quad((corner, 0.995, corner), (LIGHT_SIZE, 0, 0), (0, 0, LIGHT_SIZE))  # faces -y
    b.add_node("ceiling_lamp", b.add_mesh("ceiling_lamp", *panel, material=lamp))

    tall = shapes.box((0.3, 0.6, 0.3), (0, 0.3, 0))
    b.add_node("tall_block", b.add_mesh("tall_block", *tall, material=white), translation=(0.3, 0.0, 0.35),
               rotation=shapes.axis_angle((0, 1, 0), math.radians(20)))
    short = shapes.box((0.3, 0.3, 0.3), (0, 0.15, 0))
    block = b.add_node("moving_block", b.add_mesh("moving_block", *short, material=white),
                       translation=(0.35, 0.0, 0.7))
    end = TIMELINE.duration
    b.add_animation("block_slide", block, "translation", [0.0, end], [[0.35, 0.0, 0.7], [0.75, 0.0, 0.65]])
    b.add_animation("block_slide", block, "rotation", [0.0, end],
                    [shapes.axis_angle((0, 1, 0), 0.0), shapes.axis_angle((0, 1, 0), math.radians(-30))])

    camera = b.add_camera("camera", yfov=math.radians(40), znear=0.05, zfar=10.0)
    b.add_node("camera", camera=camera, translation=(0.5, 0.5, 2.3))
    b.set_scene_extras({"photonloom": {"element_size": ELEMENT_SIZE, "fps": TIMELINE.fps,
                                       "frames": TIMELINE.frames}})
    return b
