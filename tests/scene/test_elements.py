"""The element mesh: edge bound, area conservation, analytic hit location, shared vertices."""
from __future__ import annotations

import numpy as np
import pytest

from pipeline.scene import ElementMesh, read_scene
from tests.conftest import basic_builder

BOX = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
BOX_FACES = np.array([0, 2, 1, 0, 3, 2, 4, 5, 6, 4, 6, 7, 0, 1, 5, 0, 5, 4,
                      2, 3, 7, 2, 7, 6, 1, 2, 6, 1, 6, 5, 0, 4, 7, 0, 7, 3])


@pytest.fixture
def scene(tmp_path):
    b = basic_builder()
    node = b.add_node("box", b.add_mesh("box", BOX, BOX_FACES, material=0), translation=(0.3, 0.5, 0.2),
                      scale=(0.5, 0.7, 0.4))
    b.add_animation("spin", node, "rotation", [0, 1], [[0, 0, 0, 1], [0, 0.6, 0, 0.8]])
    b.write(tmp_path / "box.glb")
    return read_scene(tmp_path / "box.glb")


@pytest.mark.parametrize("size", [0.05, 0.13, 0.4, 5.0])
def test_every_edge_is_at_most_element_size(scene, size):
    mesh = ElementMesh.build(scene, size)
    corners = mesh.element_positions(scene.pose_frame(1))
    edges = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2)
    assert edges.max() <= size * (1 + 1e-6)
    assert mesh.n_elements == int((mesh.triangle_n.astype(np.int64) ** 2).sum())


@pytest.mark.parametrize("frame", [1, 15, 31])
def test_areas_are_conserved(scene, frame):
    mesh = ElementMesh.build(scene, 0.1)
    state = scene.pose_frame(frame)
    tri = state.vertices.astype(np.float64)[state.faces]
    source_area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()
    assert mesh.areas(state).sum() == pytest.approx(source_area, rel=1e-6)
    assert mesh.vertex_areas(state).sum() == pytest.approx(source_area, rel=1e-6)


def test_locate_maps_source_barycentrics_to_the_same_point(scene, rng):
    mesh = ElementMesh.build(scene, 0.07)
    state = scene.pose_frame(20)
    n = 20_000
    tri = rng.integers(0, len(state.faces), n)
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    element, b1, b2 = mesh.locate(tri, u, v)
    verts = state.vertices.astype(np.float64)[state.faces[tri]]
    p = (1 - u - v)[:, None] * verts[:, 0] + u[:, None] * verts[:, 1] + v[:, None] * verts[:, 2]
    corners = mesh.element_positions(state)[element]
    q = (1 - b1 - b2)[:, None] * corners[:, 0] + b1[:, None] * corners[:, 1] + b2[:, None] * corners[:, 2]
    np.testing.assert_allclose(q, p, atol=1e-5)
    assert np.all(mesh.element_triangle[element] == tri)
    assert np.all((b1 >= 0) & (b2 >= 0) & (b1 + b2 <= 1))


def test_locate_handles_corners_and_edges(scene):
    mesh = ElementMesh.build(scene, 0.1)
    tri = np.zeros(6, dtype=np.int64)
    u = np.array([0.0, 1.0, 0.0, 0.5, 0.0, 1.0 + 1e-7])
    v = np.array([0.0, 0.0, 1.0, 0.5, 0.5, 0.0])
    element, b1, b2 = mesh.locate(tri, u, v)
    lo, hi = mesh.triangle_offset[0], mesh.triangle_offset[1]
    assert np.all((element >= lo) & (element < hi))


def test_element_ids_are_stable_and_deterministic(scene):
    a = ElementMesh.build(scene, 0.1)
    b = ElementMesh.build(scene, 0.1)
    for name in ("element_vertices", "element_triangle", "vertex_local", "triangle_offset"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    # elements follow their instance: the relative geometry of a rigid box is the same in every frame
    s1, s2 = scene.pose_frame(1), scene.pose_frame(31)
    np.testing.assert_allclose(a.areas(s1), a.areas(s2), rtol=1e-9)
    moved = np.linalg.norm(a.vertex_positions(s1) - a.vertex_positions(s2), axis=1)
    box = a.vertex_instance == 1
    assert moved[box].max() > 0.1 and moved[~box].max() == 0.0


def test_vertices_shared_on_flat_faces_not_round_corners(scene):
    mesh = ElementMesh.build(scene, 0.25)
    floor = mesh.vertex_instance == 0
    n = int(mesh.triangle_n[0])
    assert floor.sum() == (n + 1) ** 2  # one lattice over both halves of the quad
    # the box: each of the 6 faces (same n per face) keeps its own lattice, nothing shared at 90 degrees
    box_tris = np.flatnonzero(np.repeat(np.arange(len(scene.instances)),
                                        [len(i.faces) for i in scene.instances]) == 1)
    per_face = [(int(mesh.triangle_n[t]) + 1) ** 2 for t in box_tris[::2]]
    assert (~floor).sum() == sum(per_face)


def test_element_source_maps_to_primitive_triangles(tmp_path):
    b = basic_builder()
    pts = np.array([[0, 1, 0], [1, 1, 0], [2, 1, 0], [0, 1, 1], [1, 1, 1]], float)
    b.add_node("mixed", b.add_mesh("mixed", pts, np.array([0, 1, 2, 0, 3, 4]), material=0))
    b.write(tmp_path / "m.glb")
    scene = read_scene(tmp_path / "m.glb")
    mesh = ElementMesh.build(scene, 0.5)
    src = mesh.element_source
    assert set(map(tuple, src[src[:, 0] == 1])) == {(1, 1)}  # triangle 0 was degenerate
    assert set(src[src[:, 0] == 0][:, 1]) == {0, 1}


def test_too_small_element_size_is_refused(scene):
    from pipeline.errors import SceneError

    with pytest.raises(SceneError, match="elements, more than"):
        ElementMesh.build(scene, 1e-4)
