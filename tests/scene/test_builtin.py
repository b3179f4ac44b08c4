"""Built-in scene generators and the GltfBuilder, checked on the files they write (read back by pygltflib).

The loader's own view of these scenes is in test_builtin_loaded.py; here we check the glTF itself:
spec details (alignment, extensions, sampler bounds), and each scene's promised content (element
counts by the element-mesh rule, frames, lights, cameras, which nodes move).
"""
from __future__ import annotations

import json
import math
import struct

import numpy as np
import pygltflib
import pytest

from pipeline.errors import LoomError
from pipeline.scene import read_scene
from pipeline.scene.builtin import BUILTIN_SCENES, atrium, room, shapes, write_builtin
from pipeline.scene.builtin.gltf_builder import GltfBuilder
from tests.scene.element_estimate import GltfData, estimate_elements, world_triangles

# name: (triangles, (min, max) elements at the scene's element_size, frames)
EXPECTED = {
    "room": (1194, (0.85 * 5_300, 1.15 * 5_300), 135),
    "atrium": (5300, (0.85 * 23_600, 1.15 * 23_600), 300),  # 1.5x the paper's element size (atrium.py)
    "cornell": (36, (50, 400), 30),
    "static": (260, (300, 1_500), 30),
}
LIGHT_KINDS = {
    "room": {"spot": 2},
    "atrium": {"directional": 1, "point": 1, "spot": 1},
    "cornell": {},
    "static": {"point": 1, "spot": 1},
}


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """Each built-in scene written once as .glb, with its parsed glTF and buffer."""
    out = tmp_path_factory.mktemp("builtin")
    cache: dict[str, tuple] = {}

    def get(name: str):
        if name not in cache:
            path = write_builtin(name, out / f"{name}.glb")
            cache[name] = (path, GltfData(path))
        return cache[name]

    return get


def _animated_nodes(gltf: pygltflib.GLTF2) -> set[str]:
    return {gltf.nodes[c.target.node].name for a in gltf.animations for c in a.channels}


def _key_times(data: GltfData) -> np.ndarray:
    return np.concatenate([data.accessor(s.input).reshape(-1) for a in data.gltf.animations for s in a.samplers])


@pytest.mark.parametrize("name", sorted(BUILTIN_SCENES))
def test_scene_writes_a_glb_with_the_promised_size(written, name):
    path, data = written(name)
    triangles, (low, high), frames = EXPECTED[name]
    assert path.read_bytes()[:4] == b"glTF"
    settings = data.gltf.scenes[data.gltf.scene].extras["photonloom"]
    assert settings["fps"] == 30 and settings["frames"] == frames
    assert sum(len(t) for t in world_triangles(data)) == triangles
    assert low <= estimate_elements(path) <= high


@pytest.mark.parametrize("name", sorted(BUILTIN_SCENES))
def test_animations_span_the_frames(written, name):
    _, data = written(name)
    settings = data.gltf.scenes[0].extras["photonloom"]
    times = _key_times(data)
    assert times.min() == 0.0
    assert times.max() == pytest.approx((settings["frames"] - 1) / settings["fps"], abs=1e-5)
    for animation in data.gltf.animations:  # input accessors carry their bounds, as the spec requires
        for sampler in animation.samplers:
            accessor = data.gltf.accessors[sampler.input]
            keys = data.accessor(sampler.input).reshape(-1)
            assert accessor.min == [keys.min()] and accessor.max == [keys.max()]
            assert np.all(np.diff(keys) > 0)


@pytest.mark.parametrize("name", sorted(BUILTIN_SCENES))
def test_lights_cameras_and_rotations(written, name):
    _, data = written(name)
    gltf = data.gltf
    lights = gltf.extensions.get("KHR_lights_punctual", {}).get("lights", [])
    kinds: dict[str, int] = {}
    for light in lights:
        kinds[light["type"]] = kinds.get(light["type"], 0) + 1
    assert kinds == LIGHT_KINDS[name]
    if lights:
        assert "KHR_lights_punctual" in gltf.extensionsUsed
    emissive = [m for m in gltf.materials if max(m.emissiveFactor) > 0]
    assert lights or emissive, "a scene needs some light"
    assert len(gltf.cameras) == 1 and gltf.cameras[0].type == "perspective"
    assert sum(n.camera is not None for n in gltf.nodes) == 1
    for node in gltf.nodes:
        if node.rotation is not None:
            assert np.linalg.norm(node.rotation) == pytest.approx(1.0, abs=1e-6)


def test_room_moves_aircraft_with_its_spot_and_torus(written):
    _, data = written("room")
    gltf = data.gltf
    assert _animated_nodes(gltf) == {"aircraft", "torus"}
    aircraft = next(n for n in gltf.nodes if n.name == "aircraft")
    child_lights = [gltf.nodes[c].extensions.get("KHR_lights_punctual") for c in aircraft.children]
    assert any(child_lights), "the spot under the aircraft must travel with it"
    mirror = [m for m in gltf.materials if m.pbrMetallicRoughness.metallicFactor >= 0.5
              and m.pbrMetallicRoughness.roughnessFactor < 0.2]
    assert mirror, "ROOM needs a specular surface"
    for material in gltf.materials:
        if material.name.startswith(("wall", "floor", "ceiling")):
            assert max(material.pbrMetallicRoughness.baseColorFactor[:3]) <= 0.8


def test_room_shell_faces_into_the_room(written):
    _, data = written("room")
    centre = np.array([room.WIDTH / 2, room.HEIGHT / 2, room.DEPTH / 2])
    names = {"floor", "ceiling", "wall_left", "wall_right", "wall_back", "wall_front"}
    for mesh in data.gltf.meshes:
        if mesh.name not in names:
            continue
        primitive = mesh.primitives[0]
        tris = data.accessor(primitive.attributes.POSITION)[data.accessor(primitive.indices).reshape(-1, 3)]
        normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
        assert np.all(np.einsum("ij,ij->i", normals, centre - tris.mean(axis=1)) > 0), mesh.name


def _unoccluded(state, points: np.ndarray, directions: np.ndarray, distances: np.ndarray) -> np.ndarray:
    """Whether each ray from ``points`` along unit ``directions`` travels ``distances`` without a hit."""
    from embreex import mesh_construction, rtcore_scene

    scene = rtcore_scene.EmbreeScene()
    mesh_construction.TriangleMesh(scene, state.vertices.astype(np.float32), state.faces.astype(np.int32))
    origins = (points + 1e-3 * directions).astype(np.float32)
    hits = scene.run(origins, directions.astype(np.float32), output=1)
    return (hits["primID"] < 0) | (hits["tfar"] > distances - 2e-3)


@pytest.mark.parametrize("frame", [1, 45, 68, 90, 135])
def test_no_room_light_sees_into_the_niche(written, frame):
    """The niche behind the partition is lit only indirectly, all through the animation."""
    state = read_scene(written("room")[0]).pose_frame(frame)
    u, v, w = np.meshgrid(np.linspace(0.05, room.NICHE_X - 0.05, 6), np.linspace(0.05, room.SOFFIT_Y - 0.05, 6),
                          np.linspace(0.05, room.NICHE_Z - 0.05, 6), indexing="ij")
    points = np.stack([u, v, w], -1).reshape(-1, 3)
    assert state.lights
    for light in state.lights:
        to_light = light.position - points
        distance = np.linalg.norm(to_light, axis=1)
        direction = to_light / distance[:, None]
        in_cone = light.spot_falloff(np.einsum("ij,j->i", -direction, light.direction)) > 0
        seen = in_cone & _unoccluded(state, points, direction, distance)
        assert not seen.any(), f"{light.definition.name} lights the niche at {points[seen][0]}"


def test_atrium_sun_enters_only_through_the_skylight(written):
    state = read_scene(written("atrium")[0]).pose_frame(1)
    sun = next(light for light in state.lights if light.kind == "directional")
    x, z = np.meshgrid(np.linspace(0.1, atrium.WIDTH - 0.1, 60), np.linspace(0.1, atrium.DEPTH - 0.1, 45))
    floor = np.stack([x.ravel(), np.full(x.size, 1e-3), z.ravel()], -1)
    towards_sun = np.broadcast_to(-sun.direction, floor.shape)
    lit = _unoccluded(state, floor, towards_sun, np.full(len(floor), np.inf))
    assert 20 < lit.sum() < 0.1 * len(floor)
    crossing = floor[lit] + towards_sun[lit] * ((atrium.HEIGHT - floor[lit, 1]) / towards_sun[lit, 1])[:, None]
    (x0, x1), (z0, z1) = atrium.SKYLIGHT_X, atrium.SKYLIGHT_Z
    assert np.all((crossing[:, 0] > x0) & (crossing[:, 0] < x1) & (crossing[:, 2] > z0) & (crossing[:, 2] < z1))


def test_atrium_exercises_every_interpolation_and_has_small_stair_triangles(written):
    _, data = written("atrium")
    gltf = data.gltf
    interpolations = {s.interpolation for a in gltf.animations for s in a.samplers}
    assert interpolations == {"LINEAR", "STEP", "CUBICSPLINE"}
    assert len(_animated_nodes(gltf) - {"camera"}) >= 3 and "camera" in _animated_nodes(gltf)
    for animation in gltf.animations:
        for sampler in animation.samplers:
            rows = 3 if sampler.interpolation == "CUBICSPLINE" else 1
            assert gltf.accessors[sampler.output].count == rows * gltf.accessors[sampler.input].count
    stairs = next(m for m in gltf.meshes if m.name == "stairs").primitives[0]
    tris = data.accessor(stairs.attributes.POSITION)[data.accessor(stairs.indices).reshape(-1, 3)]
    longest = np.linalg.norm(tris - np.roll(tris, 1, axis=1), axis=2).max()
    assert longest < 0.5 and len(tris) > 1000


def test_static_moves_only_its_camera(written):
    _, data = written("static")
    camera_nodes = {n.name for n in data.gltf.nodes if n.camera is not None}
    assert _animated_nodes(data.gltf) == camera_nodes


def test_cornell_light_panel_faces_down(written):
    _, data = written("cornell")
    mesh = next(m for m in data.gltf.meshes if m.name == "ceiling_lamp").primitives[0]
    material = data.gltf.materials[mesh.material]
    assert "KHR_materials_emissive_strength" in material.extensions and not material.doubleSided
    tris = data.accessor(mesh.attributes.POSITION)[data.accessor(mesh.indices).reshape(-1, 3)]
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    assert np.all(normals[:, 1] < 0)


def test_unknown_builtin_is_a_loom_error(tmp_path):
    with pytest.raises(LoomError, match="unknown built-in scene 'hall'; choose from atrium, cornell") as err:
        write_builtin("hall", tmp_path / "x.glb")
    assert err.value.field == "scene"


# -- the builder itself ------------------------------------------------------------------------


def _small_builder() -> GltfBuilder:
    b = GltfBuilder("small")
    lamp = b.add_material("lamp", (0.5, 0.5, 0.5), emissive=(1, 1, 1), emissive_strength=7.5)
    mesh = b.add_mesh("tri", np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]]), material=lamp)  # 36 bytes, no indices
    quad = b.add_mesh("quad", *shapes.quad((0, 0, 0), (2, 0, 0), (0, 0, 1)), material=lamp)
    node = b.add_node("tri", mesh, rotation=(0, 0, 0, 2))
    b.add_node("quad_a", quad)
    b.add_node("quad_b", quad, translation=(0, 3, 0))
    b.add_node("spot", light=b.add_spot_light("spot", (1, 1, 1), 2.0, 0.1, 0.4), children=[node])
    b.add_animation("spin", node, "rotation", [0.0, 1.0, 2.0],
                    np.tile([[0, 0, 0, 2]], (3, 3, 1)), interpolation="CUBICSPLINE")
    b.set_scene_extras({"photonloom": {"element_size": 0.5, "fps": 30, "frames": 61}})
    return b


def test_glb_layout_follows_the_spec():
    blob = _small_builder().to_glb_bytes()
    magic, version, length = struct.unpack_from("<4sII", blob)
    assert (magic, version, length) == (b"glTF", 2, len(blob))
    json_length, json_type = struct.unpack_from("<I4s", blob, 12)
    assert json_type == b"JSON" and json_length % 4 == 0
    bin_length, bin_type = struct.unpack_from("<I4s", blob, 20 + json_length)
    assert bin_type == b"BIN\0" and bin_length % 4 == 0 and 28 + json_length + bin_length == len(blob)
    doc = json.loads(blob[20:20 + json_length])
    assert all(view["byteOffset"] % 4 == 0 for view in doc["bufferViews"])
    assert {"KHR_lights_punctual", "KHR_materials_emissive_strength"} == set(doc["extensionsUsed"])
    assert doc["scenes"][0]["nodes"] == [1, 2, 3]  # the tri node is the spot's child, not a root
    assert doc["buffers"] == [{"byteLength": bin_length}]
    vertex_targets = {doc["bufferViews"][a["bufferView"]].get("target") for a in doc["accessors"]}
    assert vertex_targets == {34962, 34963, None}  # vertices, indices, animation data


@pytest.mark.parametrize("suffix, external", [(".glb", False), (".gltf", False), (".gltf", True)])
def test_written_files_read_back(tmp_path, suffix, external):
    path = _small_builder().write(tmp_path / f"small{suffix}", external_buffer=external)
    assert (tmp_path / "small.bin").exists() == external
    data = GltfData(path)
    rotation = data.accessor(data.gltf.animations[0].samplers[0].output)
    assert rotation.shape == (9, 4)
    assert np.allclose(rotation[1::3], [0, 0, 0, 1])  # key values normalised, tangents kept as given
    assert np.allclose(rotation[0::3], [0, 0, 0, 2])
    assert data.gltf.materials[0].extensions["KHR_materials_emissive_strength"] == {"emissiveStrength": 7.5}
    # At element size 0.5: tri (longest edge sqrt 2) 3^2; quad (diagonal sqrt 5) on two nodes 2 * 2 * 5^2.
    assert estimate_elements(path) == 9 + 2 * 2 * 25


@pytest.mark.parametrize("bad_call, message", [
    (lambda b: b.add_animation("a", 0, "pointer", [0.0], [[1.0]]), "path"),
    (lambda b: b.add_animation("a", 0, "translation", [0.0, 0.0], [[0, 0, 0]] * 2), "increasing"),
    (lambda b: b.add_spot_light("s", (1, 1, 1), 1.0, 0.5, 0.4), "inner < outer"),
    (lambda b: b.add_mesh("m", np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([0, 1, 3])), "indices"),
    (lambda b: b.add_mesh("m", np.array([[0, 0, 0], [1, math.nan, 0], [0, 1, 0]])), "NaN"),
    (lambda b: b.add_node("n", rotation=(0, 0, 0, 0)), "rotation"),
    (lambda b: b.write("scene.obj"), ".glb or .gltf"),
])
def test_builder_refuses_invalid_glTF(bad_call, message):
    with pytest.raises(ValueError, match=message):
        bad_call(GltfBuilder())


def test_elements_drop_zero_area_triangles_and_use_the_first_frame_pose(tmp_path):
    b = GltfBuilder()
    degenerate = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 0, 0], [1, 0, 0], [0, 1, 0]])
    node = b.add_node("m", b.add_mesh("m", degenerate))
    b.add_animation("grow", node, "scale", [0.0, 1.0], [[4, 4, 4], [1, 1, 1]])
    # At t = 0 the triangle is scaled by 4: longest edge 4 * sqrt 2 = 5.66 -> n = 6 at size 1.
    assert estimate_elements(b, 1.0) == 36
