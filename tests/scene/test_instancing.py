"""EXT_mesh_gpu_instancing (pipeline/scene/instancing.py): a node's mesh drawn once per copy at
NodeWorld x T R S x p, a mirrored copy keeping its faces' fronts outward, rotations stored as
normalized shorts, copies moving with their animated node; skinned meshes and mismatched counts
are one-line errors."""
from __future__ import annotations

import numpy as np
import pytest

from kernels.record_layout import ELEMENT_MASK
from pipeline.config import PhotonConfig
from pipeline.errors import SceneError
from pipeline.photons.raycast import RayCaster
from pipeline.photons.tracing import PhotonRange, trace_batch
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.animation import trs_matrix
from pipeline.scene.summary import describe
from tests.conftest import QUAD, QUAD_FACES, basic_builder
from tests.scene.test_visibility import BOX, BOX_FACES

TRANSLATION = np.array([[0.5, 0, 0.5], [1.5, 0, 0.5], [1.0, 0, 1.5]])
ROTATION = np.array([[0, 0, 0, 1], [0, np.sin(np.pi / 4), 0, np.cos(np.pi / 4)], [0, 0, 0, 1]])
SCALE = np.array([[1, 1, 1], [1, 2, 1], [-1, 1, 1]])  # the third copy mirrored
NODE_AT = np.array([0.0, 0.1, 0.0])


def forest(path, *, rotation=ROTATION, shorts=False, extra=None):
    """basic_builder's floor and three copies of a box on one node at NODE_AT, the node's
    translation animated 0 -> (0, 0, 0.5) over 1 s."""
    b = basic_builder()
    node = b.add_node("boxes", b.add_mesh("box", BOX, BOX_FACES, material=0), translation=NODE_AT)
    rot = b.add_accessor(np.round(rotation * 32767).astype(np.int16) if shorts else rotation.astype(np.float32))
    if shorts:
        b.gltf.accessors[rot].normalized = True
    b.gltf.nodes[node].extensions["EXT_mesh_gpu_instancing"] = {"attributes": {
        "TRANSLATION": b.add_accessor(TRANSLATION.astype(np.float32)), "ROTATION": rot,
        "SCALE": b.add_accessor(SCALE.astype(np.float32)), "_ID": b.add_accessor(np.arange(3, dtype=np.float32))}}
    b.gltf.extensionsUsed.append("EXT_mesh_gpu_instancing")
    b.gltf.extensionsRequired = ["EXT_mesh_gpu_instancing"]
    b.add_animation("slide", node, "translation", [0, 1], [NODE_AT, NODE_AT + [0, 0, 0.5]])
    if extra:
        extra(b, node)
    return b.write(path)


def _copies(scene):
    return [inst for inst in scene.instances if inst.name.startswith("boxes/")]


def test_each_copy_is_placed_by_node_world_times_its_own_trs(tmp_path):
    scene = read_scene(forest(tmp_path / "forest.glb"))
    copies = _copies(scene)
    assert [c.name for c in copies] == [f"boxes/box[0]#{k}" for k in range(3)]
    state = scene.pose(0.5)
    first = np.cumsum([0] + [len(i.vertices) for i in scene.instances])
    for k, inst in enumerate(copies):
        world = trs_matrix(NODE_AT + [0, 0, 0.25], [0, 0, 0, 1], [1, 1, 1]) @ trs_matrix(
            TRANSLATION[k], ROTATION[k], SCALE[k])
        want = BOX @ world[:3, :3].T + world[:3, 3]
        np.testing.assert_allclose(state.vertices[first[inst.index]:first[inst.index + 1]], want, atol=1e-6)
    # every face of every copy faces out of its box, the mirrored one's too
    caster = RayCaster(state)
    tri = state.vertices[state.faces].astype(np.float64)
    for inst in copies:
        rows = state.triangle_instance == inst.index
        centre = state.vertices[first[inst.index]:first[inst.index + 1]].mean(0)
        outward = np.einsum("ij,ij->i", caster.normals[rows], tri[rows].mean(1) - centre)
        assert np.all(outward > 0), inst.name
    assert any("2 meshes, 4 instances" in line for line in describe(scene))  # the floor and three copies
    assert ElementMesh.build(scene).n_elements > 0


def test_rotations_as_normalized_shorts(tmp_path):
    floats = read_scene(forest(tmp_path / "f.glb"))
    shorts = read_scene(forest(tmp_path / "s.glb", shorts=True))
    np.testing.assert_allclose(shorts.pose(0).vertices, floats.pose(0).vertices, atol=1e-4)


def _skin(b, node):
    b.gltf.nodes[node].skin = b.add_skin([node])
    b.bind_skin(1, 0, np.zeros((8, 4), int), np.tile([1.0, 0, 0, 0], (8, 1)))


def _short_scale(b, node):
    b.gltf.nodes[node].extensions["EXT_mesh_gpu_instancing"]["attributes"]["SCALE"] = b.add_accessor(
        np.ones((2, 3), np.float32))


def _a_million_copies(b, node):
    n = 1_000_000
    b.gltf.nodes[node].extensions["EXT_mesh_gpu_instancing"]["attributes"] = {
        "TRANSLATION": b.add_accessor(np.zeros((n, 3), np.float32))}
    b.gltf.meshes[1].primitives[0].indices = b.add_accessor(np.tile(BOX_FACES.ravel(), 2).astype(np.uint32))


@pytest.mark.parametrize("extra, match", [
    (_a_million_copies, r"nodes\[2\].extensions.EXT_mesh_gpu_instancing: 1,000,000 copies of 24 triangles exceed "
                        r"the 20,000,000 elements a scene may have"),
    (_skin, r"nodes\[2\].extensions.EXT_mesh_gpu_instancing: a skinned or morphed mesh cannot be instanced"),
    (_short_scale, r"nodes\[2\].extensions.EXT_mesh_gpu_instancing.attributes: TRANSLATION, ROTATION and SCALE "
                   r"must have one count, got \[2, 3\]"),
])
def test_instancing_that_cannot_be_drawn_is_a_one_line_error(tmp_path, extra, match):
    with pytest.raises(SceneError, match=match) as err:
        read_scene(forest(tmp_path / "bad.glb", extra=extra))
    assert "\n" not in str(err.value)


def test_a_mirrored_node_keeps_its_front_faces(tmp_path):
    # A single-sided emitter facing down, on a node mirrored in x: glTF reverses the winding of a
    # transform with a negative determinant (§3.7.2.1), so it still faces down and lights the floor

    b = basic_builder(light=False)
    panel = b.add_material("panel", (0.5, 0.5, 0.5), emissive=(1.0, 1.0, 1.0))  # single-sided, as emitters are
    down = QUAD_FACES.reshape(-1, 3)[:, ::-1].ravel()
    b.add_node("panel", b.add_mesh("panel", QUAD, down, material=panel), translation=(2, 1, 0), scale=(-1, 1, 1))
    scene = read_scene(b.write(tmp_path / "mirrored.glb"))
    state = scene.pose(0)
    assert state.mirrored_instances == (1,)
    normals = RayCaster(state).normals[state.triangle_instance == 1]
    np.testing.assert_allclose(normals, [[0, -1, 0]] * 2, atol=1e-12)
    elements = ElementMesh.build(scene)
    batch = trace_batch(state, elements, PhotonRange(1, 0, 4000), PhotonConfig())
    on_floor = elements.element_instance[batch.key & ELEMENT_MASK] == 0
    assert on_floor.sum() > 1000  # the panel's photons come down onto the floor
