"""KHR_node_visibility, as Khronos's CubeVisibility sample uses it (pipeline/scene/visibility.py): a
hidden node hides its subtree's meshes and lights, not cameras; ``visible`` animated through
KHR_animation_pointer with STEP unsigned bytes shows and hides a node; a hidden mesh is met by no
ray and no photon and keeps its elements; bad booleans are one-line errors."""
from __future__ import annotations

import numpy as np
import pytest

from pipeline.config import PhotonConfig
from pipeline.errors import SceneError
from pipeline.photons.raycast import RayCaster
from pipeline.photons.tracing import PhotonRange, trace_batch
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.summary import describe
from tests.conftest import basic_builder

BOX = np.array([[x, y, z] for x in (-0.2, 0.2) for y in (0.0, 0.4) for z in (-0.2, 0.2)], np.float32)
BOX_FACES = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                      [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]], np.uint32)
LAMP_NODE = 1  # basic_builder's floor is node 0, its lamp node 1


def visible_pointer(node: int) -> str:
    return f"/nodes/{node}/extensions/KHR_node_visibility/visible"


def cubes(path, *, blink=(True, False), extra=None):
    """basic_builder's lit floor with three boxes, as CubeVisibility has them: ``hidden`` (visible
    false) and its child, never shown; ``shown``; ``blinker``, its ``visible`` keyed every 0.5 s
    from ``blink`` (STEP, repeating), a camera under ``hidden``; 4 fps (frame 3 is at 0.5 s)."""
    b = basic_builder()
    red, blue = b.add_material("red", (0.8, 0.1, 0.1)), b.add_material("blue", (0.1, 0.1, 0.8))
    hidden = b.add_node("hidden", b.add_mesh("red", BOX, BOX_FACES, material=red), translation=(0.5, 0, 0.5),
                        visible=False)
    b.add_child(hidden, b.add_node("child", b.add_mesh("red child", BOX, BOX_FACES, material=red),
                                   translation=(0, 0.5, 0)))
    b.add_node("shown", b.add_mesh("green", BOX, BOX_FACES, material=0), translation=(1.0, 0, 1.0))
    blinker = b.add_node("blinker", b.add_mesh("blue", BOX, BOX_FACES, material=blue), translation=(1.5, 0, 1.5))
    if blink is not None:
        keys = np.resize(np.asarray(blink, bool), 11)
        b.add_pointer_animation("blink", visible_pointer(blinker), np.arange(11) * 0.5, keys, "STEP")
    camera = b.add_node("camera", camera=b.add_camera("cam", yfov=0.9, znear=0.05), translation=(0.5, 2.2, 2.7),
                        rotation=(-0.33, 0, 0, 0.94))
    b.add_child(hidden, camera)
    b.set_scene_extras({"photonloom": {"fps": 4}})
    if extra:
        extra(b)
    return b.write(path)


def _instance(scene, name):
    return next(inst for inst in scene.instances if inst.name.startswith(name))


def test_a_hidden_subtree_is_left_out_and_a_blinking_node_collapses(tmp_path):
    scene = read_scene(cubes(tmp_path / "cubes.glb"))
    assert not any(inst.name.startswith(("hidden", "child")) for inst in scene.instances) and len(scene.instances) == 3
    assert {scene.nodes[i].name for i in scene.hidden_nodes} == {"hidden", "child", "camera"}
    blinker = _instance(scene, "blinker")
    tris = slice(*np.cumsum([0] + [len(i.faces) for i in scene.instances])[[blinker.index, blinker.index + 1]])
    on, off = scene.pose(0.0), scene.pose(0.5)
    assert RayCaster(on).triangle_area[tris].min() > 0
    assert RayCaster(off).triangle_area[tris].max() == 0  # collapsed: no ray meets it
    np.testing.assert_allclose(off.vertices[off.faces[tris]].reshape(-1, 3), [[1.5, 0, 1.5]] * (3 * 12))
    assert on.state_key != off.state_key and scene.pose(1.0).state_key == on.state_key
    assert scene.has_animation and scene.has_moving_geometry
    # the camera below the hidden node still renders (visibility never affects cameras)
    assert off.camera is not None and np.allclose(off.camera.to_world[:3, 3], [1.0, 2.2, 3.2])
    lines = describe(scene)
    assert any("blinker [visible]" in line for line in lines)
    assert any("2 node(s) with meshes or lights hidden throughout (KHR_node_visibility)" in line for line in lines)


def test_a_node_hidden_at_the_first_frame_keeps_the_elements_it_has_when_shown(tmp_path):
    starts_hidden = read_scene(cubes(tmp_path / "hidden.glb", blink=(False, True)))
    always_shown = read_scene(cubes(tmp_path / "shown.glb", blink=None))
    a, b = ElementMesh.build(starts_hidden), ElementMesh.build(always_shown)
    assert a.n_elements == b.n_elements and np.array_equal(a.triangle_n, b.triangle_n)


def test_photons_never_meet_a_hidden_mesh(tmp_path):
    scene = read_scene(cubes(tmp_path / "cubes.glb"))
    elements = ElementMesh.build(scene)
    blinker = _instance(scene, "blinker").index
    on_blinker = []
    for t in (0.0, 0.5):
        batch = trace_batch(scene.pose(t), elements, PhotonRange(1, 0, 20000), PhotonConfig())
        element, *_ = batch.indirect()
        on_blinker.append(int(np.sum(elements.element_instance[element] == blinker)))
    assert on_blinker[0] > 20 and on_blinker[1] == 0


def test_a_hidden_lamp_goes_out(tmp_path):
    path = cubes(tmp_path / "lamp.glb", extra=lambda b: b.add_pointer_animation(
        "lamp", visible_pointer(LAMP_NODE), [0, 1], np.array([True, False]), "STEP"))
    scene = read_scene(path)
    elements = ElementMesh.build(scene)
    assert len(scene.pose(0.5).lights) == 1 and scene.pose(1.0).lights == []
    off = trace_batch(scene.pose(1.0), elements, PhotonRange(5, 0, 4000), PhotonConfig())
    assert len(off.key) == 0 and off.photons_emitted == 4000


def test_a_file_requiring_the_extension_loads(tmp_path):
    def require(b):
        b.gltf.extensionsRequired = ["KHR_node_visibility"]
    assert len(read_scene(cubes(tmp_path / "required.glb", extra=require)).instances) == 3


def _set_interpolation(b, interpolation):
    b.gltf.animations[0].samplers[0].interpolation = interpolation


def _float_keys(b):
    b.add_pointer_animation("floats", visible_pointer(0), [0, 1], [1.0, 0.0], "STEP")


def _visible_is_a_number(b):
    b.gltf.nodes[0].extensions["KHR_node_visibility"] = {"visible": 1}


@pytest.mark.parametrize("extra, match", [
    (lambda b: _set_interpolation(b, "LINEAR"),
     r"animations\[0\].samplers\[0\]: interpolation LINEAR cannot animate a boolean \(visible\): it must be STEP"),
    (_float_keys, r"animations\[1\].samplers\[0\].output -> accessors\[\d+\]: componentType 5126 is not allowed here "
                  r"\(5121\)"),
    (lambda b: b.add_pointer_animation("far", visible_pointer(99), [0, 1], np.array([True, False]), "STEP"),
     r"animations\[1\].channels\[0\].target.extensions.KHR_animation_pointer.pointer: targets missing node 99"),
    (_visible_is_a_number, r"nodes\[0\].extensions.KHR_node_visibility.visible: .*true or false"),
])
def test_a_bad_visibility_is_a_one_line_error(tmp_path, extra, match):
    with pytest.raises(SceneError, match=match) as err:
        read_scene(cubes(tmp_path / "bad.glb", extra=extra))
    assert "\n" not in str(err.value)


def test_a_file_whose_lamp_is_hidden_throughout_is_lit_by_the_defaults_and_says_why(tmp_path):
    def hide_lamp(b):
        b.gltf.nodes[LAMP_NODE].extensions["KHR_node_visibility"] = {"visible": False}
    scene = read_scene(cubes(tmp_path / "dark.glb", blink=None, extra=hide_lamp))
    assert scene.default_lights and scene.pose(0).lights[0].node == -1  # the default sun, not the lamp
    assert any("lights are on nodes hidden throughout (KHR_node_visibility)" in n for n in scene.notices)
