"""ATRIUM: the paper's larger scene (§6, Fig. 8), 300 frames; about 23,600 elements.

The paper's element size (``PAPER_ELEMENT_SIZE``) gives 43,348 elements here (the paper: about
45,000); the scene's own is 1.5 times that, the coarsest `loom bench elements` finds within d_thr
of the paper's mesh on every frame it measured (2x is not), so each element collects 1.84 times
the photons and no segment of the default render stops at the N_frame cap (docs/04-photons.md §8).

Layout (metres, y up): a closed hall 16 x 8 x 12 (x in [0, 16], z in [0, 12]). A gallery slab at
4 m covers the back (z < 4) on columns, with a parapet along its edge; a straight flight of 20
steps (0.2 m rise, 0.3 m run, 1.6 m wide, cut into 0.2-0.3 m cells) climbs from the ground floor at
z = 10 to the gallery at z = 4 along the left wall. Two full-height columns stand in the hall. The
flat roof has a 4 x 3 m skylight; the walls and roof block the sun everywhere else.

Lights: a directional ``sun`` whose only way in is the skylight (a sun patch on the ground floor
around x 9-13, z 8.5-11.5); two point ``lamps`` under the gallery, one point lamp on the gallery,
and a wall spot lighting the stairs.

Motion (so lighting changes, as in the paper): a ``cart`` drives through the sun patch (CUBICSPLINE
translation); a ``sculpture`` torus turns on a plinth (LINEAR rotation); a ``lift`` platform rides
between the two levels (LINEAR translation); a ``skylight_shade`` jumps over half the skylight at
frame 151 and back at frame 226 (STEP), abruptly halving the sunlight; the camera walks through the
hall and looks up at the gallery and stairs. The stairs' small elements and little visual masking
are where the paper saw spatial filtering matter.
"""
from __future__ import annotations

import math

import numpy as np

from pipeline.scene.builtin import shapes
from pipeline.scene.builtin.gltf_builder import GltfBuilder
from pipeline.scene.timeline import Timeline

PAPER_ELEMENT_SIZE = 0.36  # 43,348 elements, the paper's ATRIUM mesh (§6: about 45,000)
ELEMENT_SIZE = 1.5 * PAPER_ELEMENT_SIZE  # the scene's element size (see above)
TIMELINE = Timeline(fps=30, frames=300)
WIDTH, HEIGHT, DEPTH = 16.0, 8.0, 12.0
GALLERY_Y, GALLERY_Z, SLAB = 4.0, 4.0, 0.25
SKYLIGHT_X, SKYLIGHT_Z = (6.0, 10.0), (5.0, 8.0)
STEPS, RISE, RUN, STAIR_WIDTH, STAIR_X = 20, 0.2, 0.3, 1.6, 0.6
PANEL_CELL = 1.0  # architecture is cut into cells of about 1 m so no face is a long sliver
WELL_HEIGHT = 0.6
STAIR_GAP = 0.02  # keeps the flight's back face off the slab's front face (no coplanar overlap)
SUN_DIRECTION = (0.35, -1.0, 0.45)  # the way sunlight travels


def _add_hall(b: GltfBuilder) -> None:
    """Floor, walls and the roof around the skylight, all facing into the hall.

    Single-sided (glTF ``doubleSided`` false): each is one sheet whose back is the outside of the
    building, where the sun falls on the roof and walls. Double-sided, that light was recorded on
    the sheets' elements, whose one irradiance the hall sees (8 % of the indirect energy at frame
    151 came in through the roof's and the well's backs), and the sun's photons were spent on it."""
    stone = b.add_material("floor_stone", (0.5, 0.48, 0.45), double_sided=False)
    plaster = b.add_material("wall_plaster", (0.7, 0.68, 0.64), double_sided=False)
    ochre = b.add_material("wall_ochre", (0.75, 0.5, 0.2), double_sided=False)
    roof = b.add_material("roof_white", (0.75, 0.75, 0.75), double_sided=False)
    (x0, x1), (z0, z1) = SKYLIGHT_X, SKYLIGHT_Z
    at_roof = lambda x, z: (x, HEIGHT, z)  # noqa: E731 - a point on the roof plane
    roof_parts = shapes.merge([  # four quads around the opening, facing down
        shapes.panel(at_roof(0, 0), (WIDTH, 0, 0), (0, 0, z0), PANEL_CELL),
        shapes.panel(at_roof(0, z1), (WIDTH, 0, 0), (0, 0, DEPTH - z1), PANEL_CELL),
        shapes.panel(at_roof(0, z0), (x0, 0, 0), (0, 0, z1 - z0), PANEL_CELL),
        shapes.panel(at_roof(x1, z0), (WIDTH - x1, 0, 0), (0, 0, z1 - z0), PANEL_CELL),
    ])
    up = (0, WELL_HEIGHT, 0)
    well = shapes.merge([  # the skylight well's four sides facing into it; open top and bottom
        shapes.panel(at_roof(x0, z0), up, (0, 0, z1 - z0), PANEL_CELL),
        shapes.panel(at_roof(x1, z0), (0, 0, z1 - z0), up, PANEL_CELL),
        shapes.panel(at_roof(x0, z0), (x1 - x0, 0, 0), up, PANEL_CELL),
        shapes.panel(at_roof(x0, z1), up, (x1 - x0, 0, 0), PANEL_CELL),
    ])
    shell = shapes.room_shell(WIDTH, HEIGHT, DEPTH, cell=PANEL_CELL)  # its ceiling is replaced by the roof
    surfaces = [
        ("floor", shell["floor"], stone),
        ("wall_left", shell["wall_left"], plaster),
        ("wall_right", shell["wall_right"], ochre),
        ("wall_back", shell["wall_back"], plaster),
        ("wall_front", shell["wall_front"], plaster),
        ("roof", roof_parts, roof),
        ("skylight_well", well, roof),
    ]
    for name, (positions, indices), material in surfaces:
        b.add_node(name, b.add_mesh(name, positions, indices, material))


def _add_gallery_and_stairs(b: GltfBuilder) -> None:
    """The gallery slab with its parapet and columns, the stairs, and two full-height columns."""
    concrete = b.add_material("concrete", (0.6, 0.6, 0.58))
    timber = b.add_material("stair_timber", (0.55, 0.38, 0.22))
    slab = shapes.box((WIDTH, SLAB, GALLERY_Z), (WIDTH / 2, GALLERY_Y - SLAB / 2, GALLERY_Z / 2),
                     cell=PANEL_CELL)
    stair_gap = STAIR_X + STAIR_WIDTH
    parapet_length = WIDTH - stair_gap
    parapet = shapes.box((parapet_length, 1.0, 0.12),
                         (stair_gap + parapet_length / 2, GALLERY_Y + 0.5, GALLERY_Z - 0.06), cell=PANEL_CELL)
    b.add_node("gallery", b.add_mesh("gallery", *shapes.merge([slab, parapet]), material=concrete))
    column = b.add_mesh("gallery_column", *shapes.box((0.4, GALLERY_Y - SLAB, 0.4), cell=PANEL_CELL), material=concrete)
    for k, x in enumerate((4.0, 8.0, 12.0)):
        b.add_node(f"gallery_column_{k}", column, translation=(x, (GALLERY_Y - SLAB) / 2, GALLERY_Z - 0.4))
    pillar = b.add_mesh("hall_column", *shapes.box((0.6, HEIGHT, 0.6), cell=PANEL_CELL), material=concrete)
    for k, x in enumerate((5.5, 13.0)):
        b.add_node(f"hall_column_{k}", pillar, translation=(x, HEIGHT / 2, 7.0))
    # Built climbing along +z from the origin, then turned 180 degrees about y to climb towards -z.
    flight = shapes.stairs(STEPS, STAIR_WIDTH, RISE, RUN, cells_across=8, bottom=False)
    b.add_node("stairs", b.add_mesh("stairs", *flight, material=timber),
               translation=(STAIR_X + STAIR_WIDTH, 0.0, GALLERY_Z + STAIR_GAP + STEPS * RUN),
               rotation=shapes.axis_angle((0, 1, 0), math.pi))


def _add_lights(b: GltfBuilder) -> None:
    """Sun through the skylight, three point lamps, one spot on the stairs."""
    sun = b.add_directional_light("sun", (1.0, 0.95, 0.85), 40.0)
    b.add_node("sun", rotation=shapes.look_at((0, 0, 0), SUN_DIRECTION), light=sun)
    lamp = b.add_point_light("lamp", (1.0, 0.85, 0.6), 12.0)
    for k, position in enumerate([(6.0, 3.2, 2.0), (12.0, 3.2, 2.0), (10.0, 6.8, 1.5)]):
        b.add_node(f"lamp_{k}", translation=position, light=lamp)
    stair_spot = b.add_spot_light("stair_spot", (0.9, 0.95, 1.0), 30.0,
                                  inner_cone_angle=math.radians(20), outer_cone_angle=math.radians(32))
    eye, target = (4.5, 6.5, 8.5), (STAIR_X + STAIR_WIDTH / 2, 2.0, 7.0)
    b.add_node("stair_spot", translation=eye, rotation=shapes.look_at(eye, target), light=stair_spot)


def _add_moving_objects(b: GltfBuilder) -> None:
    """Cart (CUBICSPLINE), sculpture (LINEAR rotation), lift (LINEAR), skylight shade (STEP)."""
    red = b.add_material("cart_red", (0.75, 0.1, 0.08))
    blue = b.add_material("sculpture_blue", (0.1, 0.2, 0.75))
    steel = b.add_material("brushed_steel", (0.8, 0.8, 0.82), metallic=1.0, roughness=0.35)
    grey = b.add_material("shade_grey", (0.4, 0.4, 0.4))

    cart = b.add_node("cart", b.add_mesh("cart", *shapes.box((1.2, 0.8, 0.8), (0, 0.4, 0), cell=0.5), material=red))
    keys = [TIMELINE.time(f) for f in (1, 100, 200, 300)]
    values = np.array([[3.0, 0.0, 10.0], [8.0, 0.0, 10.2], [12.5, 0.0, 9.6], [14.0, 0.0, 10.0]])
    tangents = np.array([[2.0, 0.0, 0.0], [1.8, 0.0, 0.0], [1.2, 0.0, -0.1], [0.5, 0.0, 0.0]])
    spline = np.stack([tangents, values, tangents], axis=1)  # in-tangent, value, out-tangent per key
    b.add_animation("cart_drive", cart, "translation", keys, spline, interpolation="CUBICSPLINE")

    plinth = b.add_mesh("plinth", *shapes.box((0.8, 1.0, 0.8), (0, 0.5, 0)), material=steel)
    b.add_node("plinth", plinth, translation=(8.0, 0.0, 7.0))
    ring = shapes.torus(0.7, 0.18, 36, 12)
    sculpture = b.add_node("sculpture", b.add_mesh("sculpture", *ring, material=blue,
                                                   normals=shapes.torus_normals(ring[0], 0.7)),
                           translation=(8.0, 1.9, 7.0))
    turn_keys = np.linspace(0.0, TIMELINE.duration, 9)
    turns = [shapes.multiply_quaternions(shapes.axis_angle((0, 1, 0), a), shapes.axis_angle((1, 0, 0), math.pi / 2))
             for a in np.linspace(0.0, 2 * math.pi, 9)]
    b.add_animation("sculpture_turn", sculpture, "rotation", turn_keys, turns)

    lift = b.add_node("lift", b.add_mesh("lift", *shapes.box((1.5, 0.15, 1.5), cell=0.5), material=steel),
                      translation=(14.5, 0.1, 5.0))
    lift_keys = [TIMELINE.time(f) for f in (1, 60, 130, 170, 240, 300)]
    heights = [0.1, 0.1, GALLERY_Y, GALLERY_Y, 0.1, 0.1]
    b.add_animation("lift_ride", lift, "translation", lift_keys, [[14.5, h, 5.0] for h in heights])

    shade = b.add_node("skylight_shade", b.add_mesh("skylight_shade", *shapes.box((2.0, 0.05, 3.0), cell=0.5),
                                                     material=grey))
    parked, covering = (3.0, HEIGHT - 0.2, 6.5), (9.0, HEIGHT - 0.2, 6.5)
    b.add_animation("shade_steps", shade, "translation", [TIMELINE.time(f) for f in (1, 151, 226)],
                    [parked, covering, parked], interpolation="STEP")


def _add_camera(b: GltfBuilder) -> None:
    """A camera walking in from the front right towards the stairs, looking at the gallery."""
    camera = b.add_camera("camera", yfov=math.radians(60), znear=0.05, zfar=60.0)
    path = [((14.0, 1.7, 11.5), (8.0, 2.5, 4.0)), ((11.0, 1.7, 11.0), (6.0, 3.0, 4.0)),
            ((7.0, 1.8, 11.2), (3.0, 3.5, 5.0)), ((5.0, 2.0, 11.5), (1.5, 4.0, 4.0))]
    keys = np.linspace(0.0, TIMELINE.duration, len(path))
    node = b.add_node("camera", camera=camera, translation=path[0][0], rotation=shapes.look_at(*path[0]))
    b.add_animation("camera_walk", node, "translation", keys, [eye for eye, _ in path])
    b.add_animation("camera_walk", node, "rotation", keys, [shapes.look_at(eye, at) for eye, at in path])


def build() -> GltfBuilder:
    """The ATRIUM scene (see the module docstring)."""
    b = GltfBuilder("atrium")
    _add_hall(b)
    _add_gallery_and_stairs(b)
    _add_lights(b)
    _add_moving_objects(b)
    _add_camera(b)
    b.set_scene_extras({"photonloom": {"element_size": ELEMENT_SIZE, "fps": TIMELINE.fps,
                                       "frames": TIMELINE.frames}})
    return b
