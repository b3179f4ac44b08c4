"""Photon tracing against analytic values (real Embree), each within 3 standard errors.

The standard error of an estimate comes from K independent batches (different batch seeds):
SE = std / sqrt(K). Records are turned back into world positions through the element mesh.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pipeline.config import PhotonConfig
from pipeline.photons.tracing import PhotonRange, trace_batch
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.builtin.gltf_builder import GltfBuilder
from pipeline.store import DIRECT_BIT, ELEMENT_MASK, PARITY_BIT

K = 8  # independent batches per estimate


def _plane(b, material, half=10.0, y=0.0):
    quad = np.array([[-half, y, -half], [half, y, -half], [half, y, half], [-half, y, half]], float)
    return b.add_mesh("plane", quad, np.array([0, 2, 1, 0, 3, 2]), material=material)


def _load(b, tmp_path, name, element_size):
    b.set_scene_extras({"photonloom": {"element_size": element_size}})
    scene = read_scene(b.write(tmp_path / name))
    return scene, ElementMesh.build(scene), scene.pose_frame(1)


def _batches(state, elements, n, max_depth=8):
    """K independent batches: disjoint photon index ranges of one frame."""
    return [trace_batch(state, elements, PhotonRange(1, b * n, n), PhotonConfig(seed=7, photon_depth=max_depth))
            for b in range(K)]


def _positions(batch, elements, state):
    elem = (batch.key & ELEMENT_MASK).astype(np.int64)
    b = batch.bary.astype(np.float64) / 65535.0
    c = elements.element_positions(state)[elem]
    return (1 - b[:, :1] - b[:, 1:]) * c[:, 0] + b[:, :1] * c[:, 1] + b[:, 1:] * c[:, 2]


def _assert_within_3se(estimates, expected):
    estimates = np.asarray(estimates)
    se = estimates.std(ddof=1) / np.sqrt(len(estimates))
    assert abs(estimates.mean() - expected) <= 3 * se + 1e-12, (estimates.mean(), expected, se)
    assert se < 0.05 * abs(expected)  # the test has power: the error bar is tight


def _rect_solid_angle(a, b, h):
    """Solid angle of an a x b (half-sides) rectangle centred h below a point (Mathar 2014)."""
    return 4 * np.arctan(a * b / (h * np.sqrt(a * a + b * b + h * h)))


def test_point_light_irradiance_on_a_plane(tmp_path):
    b = GltfBuilder()
    white = b.add_material("white", (0.5, 0.5, 0.5))
    b.add_node("plane", _plane(b, white))
    intensity, h = 10.0, 2.0
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), intensity), translation=(0, h, 0))
    scene, elements, state = _load(b, tmp_path, "plane.glb", 0.5)
    n = 40_000
    for a in (0.5, 2.0):
        est = []
        for batch in _batches(state, elements, n, max_depth=1):
            p = _positions(batch, elements, state)
            inside = (np.abs(p[:, 0]) <= a) & (np.abs(p[:, 2]) <= a) & ((batch.key & DIRECT_BIT) > 0)
            est.append(batch.energy[inside, 1].astype(np.float64).sum() / n)
        # flux into the square = I * solid angle; its mean irradiance is that over the area
        _assert_within_3se(np.array(est) / (4 * a * a), intensity * _rect_solid_angle(a, a, h) / (4 * a * a))


def test_spot_cone_is_respected(tmp_path):
    b = GltfBuilder()
    white = b.add_material("white", (0.5, 0.5, 0.5))
    b.add_node("plane", _plane(b, white))
    inner, outer, h, intensity = 0.2, 0.4, 3.0, 50.0
    spot = b.add_spot_light("spot", (1, 1, 1), intensity, inner_cone_angle=inner, outer_cone_angle=outer)
    down = [-np.sin(np.pi / 4), 0, 0, np.cos(np.pi / 4)]
    b.add_node("spot", light=spot, translation=(0, h, 0), rotation=down)
    scene, elements, state = _load(b, tmp_path, "spot.glb", 0.5)
    batches = _batches(state, elements, 40_000, max_depth=1)
    for batch in batches:
        r = np.hypot(*_positions(batch, elements, state)[:, [0, 2]].T)
        assert r.max() <= h * np.tan(outer) * (1 + 1e-3)
        assert r.max() >= h * np.tan(outer) * 0.97  # the fall-off zone is reached
    # inside the inner cone the irradiance is the full I cos(theta) / r^2
    a = 0.3  # a 0.6 x 0.6 square lies inside the inner cone (tan 0.2 * 3 = 0.61 > 0.3 * sqrt 2)
    est = []
    for batch in batches:
        p = _positions(batch, elements, state)
        inside = (np.abs(p[:, 0]) <= a) & (np.abs(p[:, 2]) <= a)
        est.append(batch.energy[inside, 0].astype(np.float64).sum() / 40_000)
    _assert_within_3se(est, intensity * _rect_solid_angle(a, a, h))


def _closed_box(b, material, size=2.0):
    v = np.array([[x, y, z] for x in (0, size) for y in (0, size) for z in (0, size)], float)
    # 6 faces, outward winding does not matter: surfaces reflect on both faces
    faces = np.array([[0, 1, 3, 0, 3, 2], [4, 6, 7, 4, 7, 5], [0, 4, 5, 0, 5, 1],
                      [2, 3, 7, 2, 7, 6], [0, 2, 6, 0, 6, 4], [1, 5, 7, 1, 7, 3]]).ravel()
    return b.add_mesh("box", v, faces, material=material)


@pytest.mark.parametrize("rho", [0.3, 0.6])
def test_furnace_indirect_energy(tmp_path, rho):
    """In a closed box of albedo rho, indirect energy deposited = Phi rho / (1 - rho)."""
    b = GltfBuilder()
    grey = b.add_material("grey", (rho, rho, rho))
    b.add_node("box", _closed_box(b, grey))
    intensity = 3.0
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), intensity), translation=(1.0, 1.1, 0.9))
    scene, elements, state = _load(b, tmp_path, f"box{rho}.glb", 0.5)
    n = 20_000
    phi = 4 * np.pi * intensity
    direct, indirect = [], []
    for batch in _batches(state, elements, n, max_depth=200):
        is_direct = (batch.key & DIRECT_BIT) > 0
        direct.append(batch.energy[is_direct, 2].astype(np.float64).sum() / n)
        indirect.append(batch.energy[~is_direct, 2].astype(np.float64).sum() / n)
    assert np.allclose(direct, phi, rtol=1e-5)  # every photon's first hit is on a wall
    _assert_within_3se(indirect, phi * rho / (1 - rho))


def test_red_wall_bleeds_onto_white_floor(tmp_path):
    b = GltfBuilder()
    white = b.add_material("white", (0.8, 0.8, 0.8))
    red = b.add_material("red", (0.8, 0.1, 0.1))
    b.add_node("floor", _plane(b, white, half=2.0))
    wall = np.array([[-2, 0, -2], [-2, 0, 2], [-2, 4, 2], [-2, 4, -2]], float)
    b.add_node("wall", b.add_mesh("wall", wall, np.array([0, 1, 2, 0, 2, 3]), material=red))
    spot = b.add_spot_light("spot", (1, 1, 1), 100.0, inner_cone_angle=0.3, outer_cone_angle=0.5)
    west = [0, np.sin(np.pi / 4), 0, np.cos(np.pi / 4)]  # -Z turned to -X: the spot lights the red wall
    b.add_node("spot", light=spot, translation=(1.5, 2, 0), rotation=west)
    scene, elements, state = _load(b, tmp_path, "bleed.glb", 0.25)
    floor_rgb = []
    for batch in _batches(state, elements, 20_000, max_depth=4):
        p = _positions(batch, elements, state)
        on_floor = (np.abs(p[:, 1]) < 1e-4) & ((batch.key & DIRECT_BIT) == 0)
        floor_rgb.append(batch.energy[on_floor].astype(np.float64).sum(axis=0))
    rgb = np.mean(floor_rgb, axis=0)
    assert rgb[0] > 3 * rgb[1] and rgb[0] > 3 * rgb[2]


def test_deterministic_and_parity_split(tmp_path):
    b = GltfBuilder()
    white = b.add_material("white", (0.6, 0.6, 0.6))
    b.add_node("box", _closed_box(b, white))
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 1.0), translation=(1, 1, 1))
    scene, elements, state = _load(b, tmp_path, "det.glb", 0.5)
    photons, config = PhotonRange(frame=5, start=17, count=3001), PhotonConfig(seed=3, photon_depth=6)
    one = trace_batch(state, elements, photons, config)
    two = trace_batch(state, elements, photons, config)
    for name in ("key", "bary", "energy"):
        assert getattr(one, name).tobytes() == getattr(two, name).tobytes()
    for other_photons, other_config in ((photons, config.replace(seed=4)), (replace(photons, frame=6), config),
                                        (replace(photons, start=18), config)):
        other = trace_batch(state, elements, other_photons, other_config)
        assert one.key.tobytes() != other.key.tobytes()
    # photon indices 17..3017: 1501 odd, 1500 even; their direct hits split exactly so
    direct = (one.key & DIRECT_BIT) > 0
    odd = (one.key & PARITY_BIT) > 0
    assert (direct & odd).sum() == 1501 and (direct & ~odd).sum() == 1500


def _sorted_records(batch):
    order = np.lexsort((batch.energy[:, 2], batch.energy[:, 1], batch.energy[:, 0],
                        batch.bary[:, 1], batch.bary[:, 0], batch.key))
    return batch.key[order], batch.bary[order], batch.energy[order]


@pytest.fixture(scope="module")
def glossy_room(tmp_path_factory):
    """Diffuse, mirror and glossy surfaces and two kinds of light: every branch of the bounce."""
    b = GltfBuilder()
    white = b.add_material("white", (0.7, 0.6, 0.5))
    mirror = b.add_material("mirror", (0.9, 0.9, 0.9), metallic=1.0, roughness=0.05)
    glossy = b.add_material("glossy", (0.8, 0.7, 0.9), metallic=1.0, roughness=0.4)
    b.add_node("box", _closed_box(b, white, size=3.0))
    quad = np.array([[0.5, 0.2, 0.5], [2.5, 0.2, 0.5], [2.5, 0.2, 2.5], [0.5, 0.2, 2.5]], float)
    b.add_node("mirror", b.add_mesh("mirror", quad, np.array([0, 2, 1, 0, 3, 2]), material=mirror))
    b.add_node("glossy", b.add_mesh("glossy", quad + [0, 2.0, 0], np.array([0, 2, 1, 0, 3, 2]), material=glossy))
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 5.0), translation=(1.5, 1.2, 1.5))
    spot = b.add_spot_light("spot", (1, 0.5, 0.2), 20.0, inner_cone_angle=0.3, outer_cone_angle=0.6)
    b.add_node("spot", light=spot, translation=(0.3, 1.5, 0.3))
    path = tmp_path_factory.mktemp("glossy") / "glossy.glb"
    b.set_scene_extras({"photonloom": {"element_size": 0.3}})
    scene = read_scene(b.write(path))
    return scene, ElementMesh.build(scene), scene.pose_frame(1)


def test_opencl_tracer_equals_numpy_reference(glossy_room):
    """The bounce kernel and its NumPy twin give bit-identical records over whole photon paths."""
    scene, elements, state = glossy_room
    photons, config = PhotonRange(frame=3, start=0, count=20_000), PhotonConfig(seed=11, photon_depth=12)
    cl = trace_batch(state, elements, photons, config, backend="opencl")
    ref = trace_batch(state, elements, photons, config, backend="numpy")
    assert cl.rays_cast == ref.rays_cast and len(cl.key) > 20_000
    for a, b in zip(_sorted_records(cl), _sorted_records(ref)):
        assert a.tobytes() == b.tobytes()


def test_records_do_not_depend_on_batch_boundaries(glossy_room):
    """Photon i's path depends only on (seed, frame, i): one batch equals two half batches."""
    scene, elements, state = glossy_room
    config = PhotonConfig(seed=2, photon_depth=8)
    whole = trace_batch(state, elements, PhotonRange(9, 0, 6000), config)
    first = trace_batch(state, elements, PhotonRange(9, 0, 2500), config)
    rest = trace_batch(state, elements, PhotonRange(9, 2500, 3500), config)
    from pipeline.photons.tracing import PhotonBatch

    halves = PhotonBatch(np.concatenate([first.key, rest.key]), np.concatenate([first.bary, rest.bary]),
                         np.concatenate([first.energy, rest.energy]), 6000, 0)
    for a, b in zip(_sorted_records(whole), _sorted_records(halves)):
        assert a.tobytes() == b.tobytes()


def _skylit_hall(tmp_path, double_sided: bool):
    """A 10 x 10 floor (y = 0, facing up) under a roof sheet (y = 2, facing down) with a 1 x 1 hole
    at its centre, both single-sided unless ``double_sided``, and a sun straight down."""
    from pipeline.scene.builtin import shapes

    b = GltfBuilder()
    grey = b.add_material("grey", (0.5, 0.5, 0.5), double_sided=double_sided)
    floor = shapes.panel((-5, 0, -5), (0, 0, 10), (10, 0, 0), 1.0)
    roof = shapes.merge([shapes.panel((x0, 2, z0), (dx, 0, 0), (0, 0, dz), 1.0) for x0, z0, dx, dz in
                         ((-5, -5, 10, 4.5), (-5, 0.5, 10, 4.5), (-5, -0.5, 4.5, 1), (0.5, -0.5, 4.5, 1))])
    b.add_node("floor", b.add_mesh("floor", *floor, material=grey))
    b.add_node("roof", b.add_mesh("roof", *roof, material=grey))
    sun = b.add_directional_light("sun", (1, 1, 1), 3.0)
    b.add_node("sun", rotation=shapes.look_at((0, 0, 0), (0, -1, 0)), light=sun)
    return _load(b, tmp_path, "hall.glb", 0.5)


def _hall_hits(tmp_path, double_sided):
    """Per batch of 20,000 sun photons (first hits only) in the skylit hall: the batch, each hit's
    element, whether it is on the roof, and its position."""
    scene, elements, state = _skylit_hall(tmp_path, double_sided=double_sided)
    roof = scene.instances.index(next(i for i in scene.instances if i.name.startswith("roof")))
    lo, hi = elements.instance_elements[roof], elements.instance_elements[roof + 1]
    for batch in _batches(state, elements, 20_000, max_depth=1):
        elem = (batch.key & ELEMENT_MASK).astype(np.int64)
        yield batch, elem, (elem >= lo) & (elem < hi), _positions(batch, elements, state)


def test_sun_through_a_skylight_lights_the_floor_and_not_the_roof_from_outside(tmp_path):
    """A single-sided roof has no outside: the sun's photons that reach its back are absorbed, so the
    roof's elements record none from above, and the sun emits from its projection map, so nearly
    every photon comes through the hole, with the floor's irradiance under it still E.

    Emitted over the whole disk covering the scene instead, about 1 % of the sun's photons would
    come through the hole, and those recorded on the roof's top would light the room below through
    the roof elements' one irradiance."""
    estimates, on_floor = [], []
    for batch, elem, on_roof, p in _hall_hits(tmp_path, double_sided=False):
        assert not on_roof.any()  # depth 1: only first hits, all from above
        under = (np.abs(p[:, 0]) < 0.5) & (np.abs(p[:, 2]) < 0.5)
        on_floor.append(len(elem) / batch.photons_emitted)
        estimates.append(batch.energy[under, 1].astype(np.float64).sum() / batch.photons_emitted / 1.0)
    _assert_within_3se(estimates, 3.0)  # E = 3 W/m^2 over the 1 m^2 under the hole
    assert np.mean(on_floor) > 0.5


def test_a_double_sided_roof_keeps_the_light_on_its_top(tmp_path):
    """Double-sided (the builder's default), the roof's top is a surface: the sun lights it, its
    projection map covers it, and the light through the hole is the same E."""
    estimates, roof_flux = [], []
    for batch, _, on_roof, p in _hall_hits(tmp_path, double_sided=True):
        under = ~on_roof & (np.abs(p[:, 0]) < 0.5) & (np.abs(p[:, 2]) < 0.5)
        estimates.append(batch.energy[under, 1].astype(np.float64).sum() / batch.photons_emitted)
        roof_flux.append(batch.energy[on_roof, 1].astype(np.float64).sum() / batch.photons_emitted)
    _assert_within_3se(estimates, 3.0)
    _assert_within_3se(roof_flux, 3.0 * 99.0)  # E over the roof's 100 - 1 m^2
