"""Interpolation modes, clamping, hierarchy, animated lights and cameras, through the real loader."""
from __future__ import annotations

import numpy as np
import pytest

from pipeline.config import PhotonConfig
from pipeline.errors import SceneError
from pipeline.photons.tracing import PhotonRange, trace_batch
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.animation import Sampler, slerp
from pipeline.scene.ignored import ignored
from pipeline.scene.scene_cache import SceneRef
from pipeline.scene.summary import describe
from tests.conftest import basic_builder

CUBE = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
CUBE_FACES = np.array([0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3])


def _animated_scene(tmp_path, path, times, values, interpolation, name="anim.glb"):
    b = basic_builder()
    node = b.add_node("mover", b.add_mesh("tet", CUBE, CUBE_FACES, material=0))
    b.add_animation("a", node, path, times, values, interpolation)
    b.write(tmp_path / name)
    scene = read_scene(tmp_path / name)
    return scene, node


@pytest.mark.parametrize(
    "interpolation, t, expected",
    [
        ("LINEAR", 0.5, [1.0, 0.0, 0.0]),
        ("LINEAR", 1.5, [1.0, 2.0, 0.0]),
        ("STEP", 0.99, [0.0, 0.0, 0.0]),
        ("STEP", 1.0, [2.0, 0.0, 0.0]),
        ("STEP", 1.7, [2.0, 0.0, 0.0]),
        ("LINEAR", -1.0, [0.0, 0.0, 0.0]),  # clamped before the first key
        ("LINEAR", 9.0, [0.0, 4.0, 0.0]),  # clamped after the last key
    ],
)
def test_translation_interpolation(tmp_path, interpolation, t, expected):
    scene, node = _animated_scene(tmp_path, "translation", [0, 1, 2], [[0, 0, 0], [2, 0, 0], [0, 4, 0]],
                                  interpolation)
    np.testing.assert_allclose(scene.world_matrices(t)[node][:3, 3], expected, atol=1e-6)


def test_cubicspline_is_hermite(tmp_path):
    # zero tangents: p(s) = 3s^2 - 2s^3 (smoothstep); tangents 1: the Hermite basis sum
    values = np.array([[[0, 0, 0], [0, 0, 0], [1, 0, 0]],  # in, value, out of key 0
                       [[1, 0, 0], [1, 1, 1], [0, 0, 0]]], dtype=float)  # key 1
    scene, node = _animated_scene(tmp_path, "translation", [0, 2], values, "CUBICSPLINE")
    s, dt = 0.25, 2.0
    h10, h01, h11 = s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    x = h10 * dt * 1.0 + h01 * 1.0 + h11 * dt * 1.0
    yz = h01 * 1.0
    np.testing.assert_allclose(scene.world_matrices(0.5)[node][:3, 3], [x, yz, yz], atol=1e-6)
    np.testing.assert_allclose(scene.world_matrices(2.0)[node][:3, 3], [1, 1, 1], atol=1e-6)


def test_rotation_slerp_halfway(tmp_path):
    q90 = [0, np.sin(np.pi / 4), 0, np.cos(np.pi / 4)]  # 90 degrees about +Y
    scene, node = _animated_scene(tmp_path, "rotation", [0, 1], [[0, 0, 0, 1], q90], "LINEAR")
    m = scene.world_matrices(0.5)[node]
    np.testing.assert_allclose(m[:3, :3] @ [1, 0, 0], [np.cos(np.pi / 4), 0, -np.sin(np.pi / 4)], atol=1e-6)
    m = scene.world_matrices(0.25)[node]
    np.testing.assert_allclose(m[:3, :3] @ [1, 0, 0], [np.cos(np.pi / 8), 0, -np.sin(np.pi / 8)], atol=1e-6)


def test_slerp_takes_the_short_arc():
    q0 = np.array([0, 0, 0, 1.0])
    q1 = -np.array([0, np.sin(0.1), 0, np.cos(0.1)])  # same rotation as +, opposite sign
    q = slerp(q0, q1, 0.5)
    assert abs(abs(q[1]) - np.sin(0.05)) < 1e-9


def test_scale_animation_changes_element_areas(tmp_path):
    from pipeline.scene import ElementMesh

    scene, node = _animated_scene(tmp_path, "scale", [0, 1], [[1, 1, 1], [2, 2, 2]], "LINEAR")
    mesh = ElementMesh.build(scene, 0.25)
    inst = [i for i in scene.instances if i.node == node][0]
    lo, hi = mesh.instance_elements[inst.index], mesh.instance_elements[inst.index + 1]
    a0 = mesh.areas(scene.pose(0.0))[lo:hi].sum()
    a1 = mesh.areas(scene.pose(1.0))[lo:hi].sum()
    assert a1 == pytest.approx(4 * a0, rel=1e-9)
    # non-uniform scale: recomputed from positions
    scene2, node2 = _animated_scene(tmp_path, "scale", [0, 1], [[1, 1, 1], [1, 3, 1]], "LINEAR", "ns.glb")
    mesh2 = ElementMesh.build(scene2, 0.25)
    state = scene2.pose(1.0)
    corners = mesh2.element_positions(state)
    direct = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    np.testing.assert_allclose(mesh2.areas(state), direct, rtol=1e-9)


def test_hierarchy_composes_parent_and_child(tmp_path):
    b = basic_builder()
    child = b.add_node("child", b.add_mesh("tet", CUBE, CUBE_FACES, material=0), translation=(1, 0, 0))
    q90 = [0, np.sin(np.pi / 4), 0, np.cos(np.pi / 4)]
    parent = b.add_node("parent", translation=(0, 5, 0), rotation=q90, scale=(2, 2, 2), children=[child])
    b.write(tmp_path / "h.glb")
    scene = read_scene(tmp_path / "h.glb")
    world = scene.world_matrices(0.0)
    # child origin: parent T * R * S * (1, 0, 0) = (0, 5, 0) + 2 * R_y(90) (1, 0, 0) = (0, 5, -2)
    np.testing.assert_allclose(world[child][:3, 3], [0, 5, -2], atol=1e-6)
    assert scene.nodes[child].parent == parent
    state = scene.pose(0.0)
    inst = [i for i in scene.instances if i.node == child][0]
    np.testing.assert_allclose(state.instance_matrices[inst.index], world[child])


def test_spot_light_on_animated_node(tmp_path):
    b = basic_builder(light=False)
    spot = b.add_spot_light("spot", (1, 0.5, 0.25), 40.0, inner_cone_angle=0.2, outer_cone_angle=0.5, range=9.0)
    down = [-np.sin(np.pi / 4), 0, 0, np.cos(np.pi / 4)]  # -Z rotated to -Y
    node = b.add_node("spotnode", light=spot, translation=(0, 3, 0), rotation=down)
    b.add_animation("fly", node, "translation", [0, 1], [[0, 3, 0], [4, 3, 0]])
    b.write(tmp_path / "spot.glb")
    scene = read_scene(tmp_path / "spot.glb")
    light = scene.pose(0.5).lights[0]
    assert light.kind == "spot"
    np.testing.assert_allclose(light.position, [2, 3, 0], atol=1e-6)
    np.testing.assert_allclose(light.direction, [0, -1, 0], atol=1e-6)
    np.testing.assert_allclose(light.radiant, [40, 20, 10])
    assert light.definition.range == 9.0
    assert light.definition.inner_cone == pytest.approx(0.2) and light.definition.outer_cone == pytest.approx(0.5)
    # glTF's recommended fall-off: 1 inside the inner cone, 0 outside the outer, smooth in between
    f = light.spot_falloff(np.cos(np.array([0.1, 0.35, 0.6])))
    assert f[0] == 1.0 and f[2] == 0.0 and 0 < f[1] < 1
    assert scene.state_key(1) != scene.state_key(scene.timeline.last)


def test_animated_camera_and_camera_choice(tmp_path):
    b = basic_builder()
    c1 = b.add_node("cam-a", camera=b.add_camera("A", 0.8, 0.1), translation=(0, 1, 5))
    b.add_node("cam-b", camera=b.add_camera("B", 0.5, 0.1), translation=(9, 9, 9))
    b.add_animation("dolly", c1, "translation", [0, 2], [[0, 1, 5], [0, 1, 1]])
    b.write(tmp_path / "cam.glb")
    scene = read_scene(tmp_path / "cam.glb")
    cam = scene.pose(1.0).camera
    assert cam.definition.name == "A"
    np.testing.assert_allclose(cam.position, [0, 1, 3], atol=1e-6)
    np.testing.assert_allclose(cam.forward, [0, 0, -1], atol=1e-9)
    assert scene.timeline.frames == 61  # 2 s at the default 30 fps, frames 1..61
    assert read_scene(tmp_path / "cam.glb", camera="B").pose(0).camera.definition.yfov == pytest.approx(0.5)
    assert scene.has_camera_motion and not scene.has_moving_geometry
    assert len(set(scene.frame_state_keys)) == 1


@pytest.mark.parametrize("external", [False, True])
def test_gltf_with_data_uri_or_external_buffer(tmp_path, external):
    b = basic_builder()
    path = b.write(tmp_path / "scene.gltf", external_buffer=external)
    text = path.read_text()
    assert ("data:application/octet-stream;base64" in text) != external
    scene = read_scene(path)
    assert scene.n_triangles == 2 and len(scene.light_defs) == 1


def test_sampler_single_key_is_constant():
    s = Sampler(np.array([0.5]), np.array([[1.0, 2.0, 3.0]]), "LINEAR", "translation")
    for t in (-1, 0.5, 3):
        np.testing.assert_array_equal(s.evaluate(t), [1, 2, 3])


def _clips(path):
    """A character's two clips of one node, as exporters write them (separate animations, same
    targets, different lengths), and a door's animation of another node, unnamed."""
    b = basic_builder()
    body = b.add_node("body", b.add_mesh("tet", CUBE, CUBE_FACES, material=0))
    door = b.add_node("door", b.add_mesh("door", CUBE, CUBE_FACES, material=0), translation=(3, 0, 0))
    b.add_node("cam", camera=b.add_camera("cam", 0.9, 0.1), translation=(1.5, 1.0, 8.0))  # looks down -z at both
    b.add_animation("idle", body, "translation", [0, 1], [[0, 0, 0], [0, 0.1, 0]])
    b.add_animation("jump", body, "translation", [0, 2], [[0, 0, 0], [0, 2, 0]])
    b.add_animation("jump", body, "rotation", [0, 2], [[0, 0, 0, 1], [0, 1, 0, 0]])
    b.add_animation("", door, "rotation", [0, 0.5], [[0, 0, 0, 1], [0, 0.7071, 0, 0.7071]])
    b.gltf.animations[-1].name = None
    return b.write(path), body


def test_clips_of_one_node_play_one_at_a_time(tmp_path):
    path, body = _clips(tmp_path / "clips.glb")
    scene = read_scene(path)
    assert scene.animations_played == ("idle", "animation 2") and scene.animations_left_out == ("jump",)
    assert scene.animation_option is None and scene.scene_hash == scene.document.digest[:16]
    assert scene.timeline.frames == 31  # idle's 1 s, not jump's 2 s
    np.testing.assert_allclose(scene.world_matrices(1.0)[body][:3, 3], [0, 0.1, 0], atol=1e-6)
    assert any("playing 'idle', 'animation 2', leaving out 'jump'" in n for n in scene.notices)
    assert "1 animation(s) jump: alternative clips of nodes idle animates; one clip plays at a time " \
           "(--animation NAME)" in ignored(scene)
    jump = read_scene(path, animation="jump")
    assert jump.animations_played == ("jump", "animation 2") and jump.animations_left_out == ("idle",)
    assert jump.timeline.frames == 61 and jump.animation_option == "jump"
    np.testing.assert_allclose(jump.world_matrices(1.0)[body][:3, 3], [0, 1, 0], atol=1e-6)
    # another clip is another scene to a photon store; naming the default clip is the default scene
    assert jump.scene_hash != scene.scene_hash
    assert read_scene(path, animation="idle").scene_hash == scene.scene_hash
    assert read_scene(path, animation="animation 2").animations_played == ("animation 2", "idle")


def test_an_unknown_clip_is_a_one_line_error(tmp_path):
    path, _ = _clips(tmp_path / "clips.glb")
    with pytest.raises(SceneError, match=r"/clips.glb: animations: no animation is named 'run' "
                                         r"\(the file has 'idle', 'jump', 'animation 2'\)$"):
        read_scene(path, animation="run")


def test_tasks_load_the_clip_the_run_chose(tmp_path):
    path, body = _clips(tmp_path / "clips.glb")
    jump = read_scene(path, animation="jump")
    ref = SceneRef(str(path), jump.scene_hash, None, 0.5, "jump")
    assert ref.scene().animations_played == jump.animations_played
    assert ref.elements().n_elements == ElementMesh.build(jump, 0.5).n_elements
    with pytest.raises(SceneError, match="changed during the run"):  # the default clip is not what was planned
        SceneRef(str(path), jump.scene_hash, None, 0.5, None).scene()


LAMP = "/extensions/KHR_lights_punctual/lights/0"
IOR = "/materials/0/extensions/KHR_materials_ior/ior"


def _pointer_lamp(path, extra=None):
    """basic_builder's lamp (10 W/sr, white) animated through KHR_animation_pointer: its intensity
    10 -> 40 over 1 s (LINEAR), its colour to (1, 0.5, 0.25) at 0.5 s (STEP), and a material's
    index of refraction, which is not animated."""
    b = basic_builder()
    b.add_pointer_animation("lamp", LAMP + "/intensity", [0, 1], [10.0, 40.0])
    b.add_pointer_animation("lamp", LAMP + "/color", [0, 0.5], [[1, 1, 1], [1, 0.5, 0.25]], "STEP")
    b.add_pointer_animation("lamp", IOR, [0, 1], [1.5, 1.3])
    if extra:
        extra(b)
    return b.write(path)


def test_a_light_animated_through_pointers(tmp_path):
    scene = read_scene(_pointer_lamp(tmp_path / "lamp.glb"))
    np.testing.assert_allclose(scene.pose(0.0).lights[0].radiant, [10, 10, 10])
    np.testing.assert_allclose(scene.pose(0.25).lights[0].radiant, [17.5, 17.5, 17.5])
    np.testing.assert_allclose(scene.pose(0.75).lights[0].radiant, [32.5, 16.25, 8.125])
    np.testing.assert_allclose(scene.pose(1.0).lights[0].radiant, [40, 20, 10])
    assert scene.timeline.frames == 31 and len(set(scene.frame_state_keys)) == 31
    assert sorted(scene.light_channels[0]) == ["color", "intensity"] and not scene.channels
    assert any("/materials/{i}/extensions/KHR_materials_ior/ior" in w and "kept at the file's values" in w
               for w in scene.warnings)
    assert not any("KHR_animation_pointer" in line for line in ignored(scene))
    np.testing.assert_allclose(scene.materials[0].albedo, (0.7, 0.7, 0.7))


def test_a_material_animated_through_pointers(tmp_path):
    # The floor's base colour turns red over 1 s; a panel's emission switches on at 0.5 s (factor
    # fixed, strength 0 -> 3): the scene has an area light, though at rest it emits nothing
    b = basic_builder(light=False)
    panel = b.add_material("panel", (0.5, 0.5, 0.5), emissive=(1.0, 0.5, 0.5), emissive_strength=0.0)
    b.add_node("panel", b.add_mesh("panel", CUBE, CUBE_FACES, material=panel), translation=(0, 2, 0))
    b.add_pointer_animation("paint", "/materials/0/pbrMetallicRoughness/baseColorFactor", [0, 1],
                            [[0.7, 0.7, 0.7, 1], [0.7, 0.0, 0.0, 1]])
    b.add_pointer_animation("switch", f"/materials/{panel}/extensions/KHR_materials_emissive_strength/emissiveStrength",
                            [0, 0.5], [0.0, 3.0], "STEP")
    scene = read_scene(b.write(tmp_path / "paint.glb"))
    assert not scene.materials[panel].is_emissive and scene.has_area_lights and not scene.default_lights
    dark, lit = scene.pose(0.25), scene.pose(0.75)
    np.testing.assert_allclose(dark.materials[0].albedo, (0.7, 0.525, 0.525))
    np.testing.assert_allclose(lit.materials[0].albedo, (0.7, 0.175, 0.175))
    assert len(dark.emissive_triangles) == 0 and len(lit.emissive_triangles) == len(CUBE_FACES) // 3
    np.testing.assert_allclose(lit.materials[panel].emission, (3.0, 1.5, 1.5))
    assert dark.state_key != lit.state_key and sorted(scene.material_channels) == [0, panel]


def test_a_camera_zooms_through_a_pointer(tmp_path):
    b = basic_builder()
    cam = b.add_camera("A", 0.8, 0.1)
    b.add_node("cam", camera=cam, translation=(0, 1, 5))
    b.add_pointer_animation("zoom", f"/cameras/{cam}/perspective/yfov", [0, 1], [0.8, 0.4])
    path = b.write(tmp_path / "zoom.glb")
    scene = read_scene(path)
    assert scene.pose(0.5).camera.definition.yfov == pytest.approx(0.6)
    assert scene.has_camera_motion and len(set(scene.frame_state_keys)) == 1  # one photon set serves all
    assert "animated   0 nodes; 1 cameras: A [yfov]" in describe(scene, None)
    b.add_pointer_animation("bad", f"/cameras/{cam}/perspective/yfov", [0, 1], [0.8, 3.2])
    with pytest.raises(SceneError, match=r"animations\[1\].samplers\[0\].output: camera yfov keys must lie in"):
        read_scene(b.write(tmp_path / "bad.glb"))


def test_a_node_pointer_is_the_core_channel(tmp_path):
    b = basic_builder()
    node = b.add_node("mover", b.add_mesh("tet", CUBE, CUBE_FACES, material=0))
    b.add_pointer_animation("move", f"/nodes/{node}/translation", [0, 1], [[0, 0, 0], [2, 0, 0]])
    scene = read_scene(b.write(tmp_path / "node.glb"))
    np.testing.assert_allclose(scene.world_matrices(0.5)[node][:3, 3], [1, 0, 0], atol=1e-6)


def test_the_photons_of_a_brighter_lamp_carry_its_power(tmp_path):
    # Same geometry, same random numbers: every photon takes the same path and carries 4x the power
    scene = read_scene(_pointer_lamp(tmp_path / "lamp.glb"))
    elements = ElementMesh.build(scene)
    dim, bright = (trace_batch(scene.pose(t), elements, PhotonRange(1, 0, 4000), PhotonConfig()) for t in (0.0, 0.25))
    assert np.array_equal(dim.key, bright.key) and len(dim.key) > 200  # the floor catches about 7 %
    np.testing.assert_allclose(bright.energy, dim.energy * 1.75, rtol=1e-6)


def test_a_cubic_intensity_may_have_falling_tangents_and_is_clamped_at_zero(tmp_path):
    # keys 10 and 0, tangents -40 (in, value, out per key): the curve dips below 0 before the end
    b = basic_builder()
    b.add_pointer_animation("fade", LAMP + "/intensity", [0, 1], [[0.0], [10.0], [-40.0], [-40.0], [0.0], [0.0]],
                            "CUBICSPLINE")
    scene = read_scene(b.write(tmp_path / "fade.glb"))
    values = [scene.pose(t).lights[0].radiant[0] for t in np.linspace(0, 1, 21)]
    assert values[0] == 10.0 and values[-1] == 0.0 and min(values) == 0.0 and 0 < values[2] < 10


def test_a_lamp_switched_off_traces_photons_that_carry_nothing(tmp_path):
    b = basic_builder()
    b.add_pointer_animation("off", LAMP + "/intensity", [0, 1], [10.0, 0.0], "STEP")
    scene = read_scene(b.write(tmp_path / "off.glb"))
    elements = ElementMesh.build(scene)
    on, off = (trace_batch(scene.pose(t), elements, PhotonRange(1, 0, 4000), PhotonConfig()) for t in (0.0, 1.0))
    assert len(on.key) > 200 and on.photons_emitted == 4000
    assert len(off.key) == 0 and off.photons_emitted == 4000 and off.stats["records"] == 0


@pytest.mark.parametrize("extra, match", [
    (lambda b: b.add_pointer_animation("bad", LAMP + "/intensity", [0, 1], [1.0, -1.0]),
     r"animations\[1\].samplers\[0\].output: light intensity keys must not be negative"),
    (lambda b: b.add_pointer_animation("bad", "/extensions/KHR_lights_punctual/lights/3/color", [0, 1],
                                       [[1, 1, 1], [0, 0, 0]]),
     r"animations\[1\].channels\[0\].target.extensions.KHR_animation_pointer.pointer: "
     r"/extensions/KHR_lights_punctual/lights/3/color points to missing light 3"),
    (lambda b: b.add_pointer_animation("bad", LAMP + "/intensity", [0, 1], [[1, 1, 1], [2, 2, 2]]),
     r"animations\[1\].samplers\[0\].output: output must be scalars for intensity"),
    (lambda b: b.add_pointer_animation("bad", "nodes/0/translation", [0, 1], [[1, 1, 1], [2, 2, 2]]),
     r"pointer 'nodes/0/translation' must be a JSON pointer string"),
])
def test_a_bad_pointer_channel_is_a_one_line_error(tmp_path, extra, match):
    with pytest.raises(SceneError, match=match):
        read_scene(_pointer_lamp(tmp_path / "bad.glb", extra))
