"""Skins and morph targets through the real loader, against poses computed by hand (glTF 2.0 §3.7.2.2,
§3.7.3, Appendix C), and what they change around them: element mesh, state keys, timeline, element size."""
from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from pipeline.cli import main
from pipeline.errors import SceneError
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.builtin.gltf_builder import GltfBuilder
from tests.scene.deforming_assets import (
    animated_morph_cube,
    cube_mesh,
    cylinder,
    morph_targets,
    rigged_simple,
    two_bone_weights,
)

PIVOT = np.array([0.0, 1.0, 1.0])  # bone1's bind position: bone0 at (0, 0, 1), bone1 one up


def _rz(degrees: float) -> np.ndarray:
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _hand_skinned(degrees: float) -> tuple[np.ndarray, np.ndarray]:
    """The two-bone cylinder bent by ``degrees`` about +Z at the pivot, each vertex the weighted
    sum of its rest position (bone0 still) and its rotation about the pivot (bone1); normals of the
    vertices bound to one bone only (the rest are checked by position)."""
    pos, nrm, _, y = cylinder(0.2, 2.0, 9, 12, axis_z=1.0)
    w1 = two_bone_weights(y, 2.0)[:, None]
    r = _rz(degrees)
    points = (1 - w1) * pos + w1 * (PIVOT + (pos - PIVOT) @ r.T)
    normals = np.where(w1 == 1, nrm @ r.T, nrm)
    return points, normals


def _instance(scene, name):
    return next(inst for inst in scene.instances if inst.name.startswith(name))


def _posed(scene, inst, t):
    """World vertices of an instance as the frame state holds them (float32) and as posed (float64)."""
    state = scene.pose(t)
    start = sum(len(i.vertices) for i in scene.instances[:inst.index])
    exact, normals = scene.deformed_vertices(inst, scene.world_matrices(t), t)
    return state, state.vertices[start:start + len(inst.vertices)], exact, normals


# bend angle at t = 0.25 of a 0..1 s, 0..90 degree key pair: slerp is linear in angle; STEP holds the
# first key; CUBICSPLINE with zero tangents blends the quaternions by h = 3s^2 - 2s^3, normalised
_H = 3 * 0.25 ** 2 - 2 * 0.25 ** 3
_CUBIC = np.degrees(2 * np.arctan2(_H * np.sin(np.pi / 4), (1 - _H) + _H * np.cos(np.pi / 4)))


@pytest.mark.parametrize("interpolation, t, degrees", [
    ("LINEAR", 0.0, 0.0), ("LINEAR", 0.25, 22.5), ("LINEAR", 1.0, 90.0), ("LINEAR", 3.0, 90.0),
    ("STEP", 0.25, 0.0), ("STEP", 1.0, 90.0), ("CUBICSPLINE", 0.25, _CUBIC), ("CUBICSPLINE", 1.0, 90.0),
])
def test_two_bone_cylinder_matches_the_hand_computed_pose(tmp_path, interpolation, t, degrees):
    path = rigged_simple(tmp_path / "rig.glb", interpolation=interpolation, times=(0.0, 1.0), light=False)
    b = read_scene(path)
    inst = _instance(b, "skinned")
    _, stored, exact, normals = _posed(b, inst, t)
    points, hand_normals = _hand_skinned(degrees)
    np.testing.assert_allclose(exact, points, atol=1e-5)  # the mesh node's (5, 0, 0) is ignored (§3.7.3.3)
    np.testing.assert_allclose(stored, points, atol=1e-5)
    one_bone = np.isin(two_bone_weights(inst.vertices[:, 1], 2.0), (0.0, 1.0))
    np.testing.assert_allclose(normals[one_bone], hand_normals[one_bone], atol=1e-5)


def test_influences_in_the_second_joint_set_count(tmp_path):
    """The upper bone's weight in JOINTS_1/WEIGHTS_1 (slot 5) or JOINTS_0 (slot 1): the same pose."""
    second = read_scene(rigged_simple(tmp_path / "a.glb", set_for_upper=1, times=(0.0, 1.0), light=False))
    first = read_scene(rigged_simple(tmp_path / "b.glb", set_for_upper=0, times=(0.0, 1.0), light=False))
    assert _instance(second, "skinned").deformation.joints.shape[1] == 8
    assert _instance(first, "skinned").deformation.joints.shape[1] == 4
    np.testing.assert_allclose(second.pose(0.5).vertices, first.pose(0.5).vertices, atol=1e-6)
    np.testing.assert_allclose(second.pose(0.5).vertices[:len(_hand_skinned(45)[0])], _hand_skinned(45)[0],
                               atol=1e-5)


def _one_target_morph(tmp_path, interpolation="LINEAR", animate=True, node_weights=None):
    """A tetrahedron on a node scaled (2, 1, 1) and translated (0, 0, 3), one target moving vertex 3
    by (0, 0.5, 0) and tilting its normal by (1, 0, 0)."""
    b = GltfBuilder()
    mat = b.add_material("m", (0.5, 0.5, 0.5))
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    nrm = np.array([[0, 0, 1]] * 4, float)
    mesh = b.add_mesh("tet", pos, np.array([0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3]), material=mat, normals=nrm)
    dp = np.zeros((4, 3))
    dp[3] = (0, 0.5, 0)
    dn = np.zeros((4, 3))
    dn[3] = (1, 0, 0)
    b.add_morph_targets(mesh, 0, [dp], normals=[dn], weights=[0.25])
    node = b.add_node("morph", mesh, scale=(2, 1, 1), translation=(0, 0, 3), weights=node_weights)
    if animate:
        keys = [[0.0], [1.0]]
        if interpolation == "CUBICSPLINE":
            keys = [[[0.0], [0.0], [0.0]], [[0.0], [1.0], [0.0]]]
        b.add_animation("w", node, "weights", [0.0, 1.0], keys, interpolation)
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 10.0), translation=(1, 2, 1))
    return read_scene(b.write(tmp_path / "morph.glb")), pos, nrm


@pytest.mark.parametrize("interpolation, t, weight", [
    ("LINEAR", 0.0, 0.0), ("LINEAR", 0.3, 0.3), ("LINEAR", 1.0, 1.0), ("STEP", 0.7, 0.0), ("STEP", 1.0, 1.0),
    ("CUBICSPLINE", 0.3, 3 * 0.09 - 2 * 0.027),  # zero tangents: the Hermite basis h01(s)
])
def test_one_target_morph_matches_the_hand_computed_pose(tmp_path, interpolation, t, weight):
    scene, pos, nrm = _one_target_morph(tmp_path, interpolation)
    inst = scene.instances[0]
    _, stored, exact, normals = _posed(scene, inst, t)
    local = pos.copy()
    local[3] += weight * np.array([0, 0.5, 0])
    world = local * [2, 1, 1] + [0, 0, 3]
    np.testing.assert_allclose(exact, world, atol=1e-5)
    np.testing.assert_allclose(stored, world, atol=1e-5)
    n3 = (np.array([0, 0, 1.0]) + weight * np.array([1.0, 0, 0])) / [2, 1, 1]  # inverse transpose of diag(2,1,1)
    np.testing.assert_allclose(normals[3], n3 / np.linalg.norm(n3), atol=1e-5)
    np.testing.assert_allclose(normals[0], [0, 0, 1], atol=1e-6)


def test_default_weights_node_over_mesh(tmp_path):
    """Without animation: node.weights override mesh.weights (glTF §3.7.2.2); mesh.weights otherwise."""
    mesh_only, pos, _ = _one_target_morph(tmp_path, animate=False)
    assert mesh_only.timeline.frames == 1
    np.testing.assert_allclose(mesh_only.pose(0.0).vertices[3], (pos[3] + [0, 0.125, 0]) * [2, 1, 1] + [0, 0, 3],
                               atol=1e-6)
    node, pos, _ = _one_target_morph(tmp_path, animate=False, node_weights=[0.75])
    np.testing.assert_allclose(node.pose(0.0).vertices[3], (pos[3] + [0, 0.375, 0]) * [2, 1, 1] + [0, 0, 3],
                               atol=1e-6)


def test_morph_only_animation_drives_the_timeline_and_state_keys(tmp_path):
    scene, _, _ = _one_target_morph(tmp_path)
    assert scene.timeline.frames == 31  # keys 0..1 s at 30 fps: not a silent 1-frame timeline
    keys = scene.frame_state_keys
    assert len(set(keys)) == 31 and scene.has_moving_geometry
    assert scene.state_key(31) == scene.pose(5.0).state_key  # clamped after the last key: equal states
    assert not scene.has_camera_motion


def test_skin_pose_changes_the_state_key_and_a_still_skin_does_not(tmp_path):
    scene = read_scene(rigged_simple(tmp_path / "rig.glb", light=False))
    keys = scene.frame_state_keys
    assert len(set(keys)) == 3  # only a joint moves: no node with a mesh is animated
    still = read_scene(rigged_simple(tmp_path / "still.glb", degrees=(30.0, 30.0), light=False))
    assert len(set(still.frame_state_keys)) == 1 and not still.has_moving_geometry


def test_element_mesh_deforms_with_the_surface_and_keeps_its_ids(tmp_path):
    scene = read_scene(rigged_simple(tmp_path / "rig.glb"))
    mesh = ElementMesh.build(scene, 0.1)
    first, last = scene.pose_frame(1), scene.pose_frame(3)
    p1, p3 = mesh.vertex_positions(first), mesh.vertex_positions(last)
    for state, p in ((first, p1), (last, p3)):
        # every element lies on its posed source triangle: the areas of a triangle's n x n elements
        # add up to the triangle's posed area, and each element vertex is a lattice point of it
        tri = state.vertices.astype(np.float64)[state.faces]
        tri_area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        np.testing.assert_allclose(np.bincount(mesh.element_triangle, mesh.areas(state)), tri_area, rtol=1e-6)
        corner0 = p[mesh.element_vertices[mesh.triangle_offset[:-1], 0]]  # lattice (0, 0) of each triangle
        np.testing.assert_allclose(corner0, tri[:, 0], atol=1e-5)
    inst = _instance(scene, "skinned").index
    on_cylinder = mesh.vertex_instance == inst
    moved = np.linalg.norm(p3 - p1, axis=1)
    top, bottom = mesh.vertex_local[:, 1] > 1.6, mesh.vertex_local[:, 1] < 0.4
    assert moved[on_cylinder & top].min() > 0.3  # the bent half swings round the pivot
    assert moved[on_cylinder & bottom].max() < 1e-6  # bone0's half stands still
    assert moved[~on_cylinder].max() == 0.0  # so does the floor
    assert mesh.n_elements == ElementMesh.build(scene, 0.1).n_elements  # built on the bind topology


def test_default_element_size_from_posed_world_bounds(tmp_path):
    """AnimatedMorphCube's cube is 0.02 wide in the file and 2 wide in the world (node scale 100):
    the element size follows the world, and the posed morph grows the bounds."""
    big = read_scene(animated_morph_cube(tmp_path / "cube.glb", light=False))
    # cube from (-1, 0, -1) to (1, 2, 1), both targets at weight 1: +1 up, +1 in x -> (-1, 0, -1)..(2, 3, 1)
    assert big.element_size == pytest.approx(np.linalg.norm([3, 3, 2]) / 50, rel=1e-6)
    assert ElementMesh.build(big).n_elements < 50_000
    small = read_scene(animated_morph_cube(tmp_path / "small.glb", scale=0.01, light=False))
    assert small.element_size == pytest.approx(np.linalg.norm([3, 3, 2]) * 1e-4 / 50, rel=1e-5)


def test_animated_morph_cube_weights_on_every_interpolation(tmp_path):
    pos, _, _ = cube_mesh()
    up, side = morph_targets(pos)
    for interpolation in ("STEP", "LINEAR", "CUBICSPLINE"):
        scene = read_scene(animated_morph_cube(tmp_path / f"{interpolation}.glb", interpolation=interpolation,
                                               times=(0.0, 1.0), weights=((0, 0), (1, 0.5)), light=False))
        w = {"STEP": (0, 0), "LINEAR": (0.5, 0.25), "CUBICSPLINE": (0.5, 0.25)}[interpolation]  # at s = 0.5
        expected = (pos + w[0] * up + w[1] * side) * 100 + [0, 1, 0]
        np.testing.assert_allclose(scene.pose(0.5).vertices, expected, atol=1e-5)


def test_loom_info_states_what_deforms(tmp_path):
    out = CliRunner().invoke(main, ["info", str(rigged_simple(tmp_path / "rig.glb"))]).output
    assert ("deforms    1 of 2 primitives posed per vertex: skinned/cylinder[0]: skin 0 (2 joints, 1 animated, "
            "up to 8 influences)") in out.splitlines()
    assert "ignored" not in out and "warning" not in out
    cube = CliRunner().invoke(main, ["info", str(animated_morph_cube(tmp_path / "cube.glb"))]).output
    assert "AnimatedMorphCube/cube[0]: 2 morph target(s), weights animated" in cube
    assert "frames     3 at 30 fps" in cube


@pytest.mark.parametrize("change, field, reason", [
    (lambda b: b.gltf.skins[0].joints.append(99), "skins[0].joints", "joint 99 is not a node"),
    (lambda b: setattr(b.gltf.skins[0], "joints", [1]), "attributes.JOINTS_1", "joint 1 is out of range"),
    (lambda b: setattr(b.gltf.meshes[0].primitives[0].attributes, "WEIGHTS_1", None), "attributes",
     "JOINTS_1 has no WEIGHTS_1"),
])
def test_bad_skins_are_one_line_errors(tmp_path, change, field, reason):
    path = rigged_simple(tmp_path / "bad.glb", light=False, edit=change)
    with pytest.raises(SceneError) as err:
        read_scene(path)
    assert "\n" not in str(err.value)
    assert str(path) in str(err.value) and field in str(err.value) and reason in str(err.value)


def test_weight_channel_of_the_wrong_width_is_refused(tmp_path):
    b = GltfBuilder()
    pos, nrm, idx = cube_mesh()
    mesh = b.add_mesh("cube", pos, idx, normals=nrm)
    b.add_morph_targets(mesh, 0, morph_targets(pos))
    node = b.add_node("cube", mesh)
    b.add_animation("w", node, "weights", [0.0, 1.0, 2.0], [[0.0], [1.0], [0.5]])  # 1 weight a key, 2 targets
    path = b.write(tmp_path / "w.glb")
    with pytest.raises(SceneError, match=r"animations\[0\].samplers\[0\].output: output must be scalars, 2 per key"):
        read_scene(path)


def test_frames_beyond_a_morph_timeline_name_the_file(tmp_path):
    scene, _, _ = _one_target_morph(tmp_path)
    out = CliRunner().invoke(main, ["render", str(scene.path), "--out", str(tmp_path / "o"), "--frames", "1-40",
                                    "--scheduler", "synchronous"])
    assert out.exit_code == 2 and not (tmp_path / "o").exists()
    assert out.output.strip() == (f"loom: error: {scene.path}: frames: frame 40 is outside the timeline 1-31 "
                                  "(31 frame(s) at 30 fps, 1 s)")


def test_unweighted_vertices_follow_their_node(tmp_path):
    """Joint at (0, 0, 2), no inverse bind matrices (identity): bound vertices move by the joint,
    the unweighted one stays where the mesh node (at (5, 0, 0)) puts it, with a warning."""
    b = GltfBuilder()
    mesh = b.add_mesh("tri", np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([0, 1, 2]))
    b.bind_skin(mesh, 0, np.zeros((3, 4), int), np.array([[1, 0, 0, 0], [1, 0, 0, 0], [0, 0, 0, 0]], float))
    joint = b.add_node("joint", translation=(0, 0, 2))
    b.add_node("tri", mesh, translation=(5, 0, 0), skin=b.add_skin([joint]))
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 10.0), translation=(0, 3, 0))
    scene = read_scene(b.write(tmp_path / "tri.glb"))
    np.testing.assert_allclose(scene.pose(0.0).vertices, [[0, 0, 2], [1, 0, 2], [5, 1, 0]], atol=1e-6)
    assert scene.warnings == ["meshes[0].primitives[0]: 1 vertex(es) have all skin weights zero: they follow "
                              "the node 'tri' unskinned"]


def _sparse_target_scene(tmp_path, indices=(3,)):
    """The one-target tetrahedron with its target as a sparse accessor without a bufferView (zeros
    but for the listed vertices), as Blender writes shape keys."""
    from pygltflib import Accessor, AccessorSparseIndices, AccessorSparseValues, Sparse

    b = GltfBuilder()
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    mesh = b.add_mesh("tet", pos, np.array([0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3]))
    views = [b.gltf.accessors[b.add_accessor(data)].bufferView for data in
             (np.array(indices, np.uint16), np.tile([0, 0.5, 0], (len(indices), 1)).astype(np.float32))]
    b.gltf.accessors.append(Accessor(count=4, componentType=5126, type="VEC3", sparse=Sparse(
        count=len(indices), indices=AccessorSparseIndices(bufferView=views[0], componentType=5123),
        values=AccessorSparseValues(bufferView=views[1]))))
    b.gltf.meshes[mesh].primitives[0].targets = [{"POSITION": len(b.gltf.accessors) - 1}]
    b.gltf.meshes[mesh].weights = [1.0]
    b.add_node("tet", mesh)
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 10.0), translation=(0, 3, 0))
    return b.write(tmp_path / "sparse.glb"), pos


def test_sparse_morph_target(tmp_path):
    path, pos = _sparse_target_scene(tmp_path)
    np.testing.assert_allclose(read_scene(path).pose(0.0).vertices, pos + np.array([[0, 0, 0]] * 3 + [[0, 0.5, 0]]),
                               atol=1e-6)
    bad, _ = _sparse_target_scene(tmp_path, indices=(3, 2))
    with pytest.raises(SceneError, match=r"accessors\[\d+\].sparse.indices: indices must increase strictly"):
        read_scene(bad)
