"""Skinned and morphed glTF files written in code by the real builder, for tests and by hand.

``rigged_simple`` and ``animated_morph_cube`` reproduce the structure of the Khronos glTF sample
models RiggedSimple (CC-BY 4.0, a cylinder skinned to two joints whose second joint rotates) and
AnimatedMorphCube (CC0, a cube with two morph targets whose weights are animated, its node scaled
100x); they are generated here rather than shipped. ``python -m tests.scene.deforming_assets DIR``
writes both into DIR.
"""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Callable

import numpy as np

from pipeline.scene.builtin.gltf_builder import GltfBuilder


def translation(x: float, y: float, z: float) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def z_rotation(degrees: float) -> list[float]:
    """Quaternion (x, y, z, w) of a rotation about +Z."""
    h = np.radians(degrees) / 2.0
    return [0.0, 0.0, float(np.sin(h)), float(np.cos(h))]


def cylinder(radius: float, height: float, rings: int, segments: int, axis_z: float = 0.0):
    """Side wall of a capped-less cylinder along +Y at x = 0, z = ``axis_z``: positions, radial
    normals, triangle indices (outward winding) and each vertex's height."""
    a = 2 * np.pi * np.arange(segments) / segments
    y = np.linspace(0.0, height, rings)
    yy, aa = np.meshgrid(y, a, indexing="ij")
    pos = np.stack([radius * np.cos(aa), yy, axis_z + radius * np.sin(aa)], -1).reshape(-1, 3)
    nrm = np.stack([np.cos(aa), np.zeros_like(aa), np.sin(aa)], -1).reshape(-1, 3)
    faces = []
    for r in range(rings - 1):
        for s in range(segments):
            i0, i1 = r * segments + s, r * segments + (s + 1) % segments
            j0, j1 = i0 + segments, i1 + segments
            faces += [i0, j0, i1, i1, j0, j1]
    return pos, nrm, np.array(faces), pos[:, 1].copy()


def two_bone_weights(y: np.ndarray, height: float) -> np.ndarray:
    """Weight of the upper bone: 0 below a quarter of the height, 1 above three quarters, linear between."""
    return np.clip((y - 0.25 * height) / (0.5 * height), 0.0, 1.0)


def rigged_simple(path: Path, *, interpolation: str = "LINEAR", times=(0.0, 2 / 30), degrees=(0.0, 90.0),
                  set_for_upper: int = 1, light: bool = True, edit: Callable | None = None) -> Path:
    """A RiggedSimple-like file: a cylinder (radius 0.2, height 2, axis x = 0, z = 1) skinned to
    ``bone0`` (translated (0, 0, 1)) and its child ``bone1`` (1 up), whose rotation about +Z is
    animated through ``degrees`` at ``times``. The upper bone's weight sits in influence slot
    ``4 * set_for_upper + 1`` (set 1: JOINTS_1/WEIGHTS_1). The mesh node is translated (5, 0, 0),
    which glTF says a skinned mesh ignores. A floor and a point light (``light``) make it renderable;
    ``edit`` may change the builder before it writes (to break the file on purpose)."""
    b = GltfBuilder()
    grey = b.add_material("grey", (0.6, 0.6, 0.6))
    red = b.add_material("red", (0.8, 0.2, 0.1))
    pos, nrm, faces, y = cylinder(0.2, 2.0, 9, 12, axis_z=1.0)
    mesh = b.add_mesh("cylinder", pos, faces, material=red, normals=nrm)
    w1 = two_bone_weights(y, 2.0)
    sets = set_for_upper + 1
    joints = np.zeros((len(pos), 4 * sets), np.uint16)
    weights = np.zeros((len(pos), 4 * sets))
    joints[:, 0], weights[:, 0] = 0, 1.0 - w1
    upper = 4 * set_for_upper + 1
    joints[:, upper], weights[:, upper] = 1, w1
    b.bind_skin(mesh, 0, joints, weights)
    bone1 = b.add_node("bone1", translation=(0, 1, 0))
    bone0 = b.add_node("bone0", translation=(0, 0, 1), children=[bone1])
    skin = b.add_skin([bone0, bone1], np.stack([np.linalg.inv(translation(0, 0, 1)),
                                                 np.linalg.inv(translation(0, 1, 1))]))
    b.add_node("skinned", mesh, translation=(5, 0, 0), skin=skin)
    keys = [z_rotation(d) for d in degrees]
    if interpolation == "CUBICSPLINE":  # zero tangents
        keys = [[[0, 0, 0, 0], k, [0, 0, 0, 0]] for k in keys]
    b.add_animation("bend", bone1, "rotation", list(times), keys, interpolation)
    if light:
        floor = np.array([[-3, 0, -2], [3, 0, -2], [3, 0, 4], [-3, 0, 4]], float)
        b.add_node("floor", b.add_mesh("floor", floor, np.array([0, 2, 1, 0, 3, 2]), material=grey))
        b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 60.0), translation=(1, 4, 3))
        cam = b.add_camera("cam", yfov=0.8, znear=0.05)
        b.add_node("cam", camera=cam, translation=(0, 1.2, 6))
    if edit is not None:
        edit(b)
    return b.write(path)


CUBE_CORNERS = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * 0.01
# Four vertices per face, outward normals: the 24-vertex cube exporters write
_FACES = [(0, [0, 1, 3, 2]), (0, [4, 6, 7, 5]), (1, [0, 4, 5, 1]), (1, [2, 3, 7, 6]), (2, [0, 2, 6, 4]),
          (2, [1, 5, 7, 3])]


def cube_mesh():
    """(24, 3) positions of a cube 0.02 wide (AnimatedMorphCube's size), normals and indices."""
    pos, nrm, idx = [], [], []
    for axis, quad in _FACES:
        corners = CUBE_CORNERS[quad]
        normal = np.zeros(3)
        normal[axis] = np.sign(corners[:, axis].mean())
        base = len(pos)
        pos += list(corners)
        nrm += [normal] * 4
        e1, e2 = corners[1] - corners[0], corners[2] - corners[0]
        tri = [0, 1, 2, 0, 2, 3] if np.dot(np.cross(e1, e2), normal) > 0 else [0, 2, 1, 0, 3, 2]
        idx += [base + i for i in tri]
    return np.array(pos), np.array(nrm), np.array(idx)


def morph_targets(pos: np.ndarray):
    """Two targets: the top (y > 0) rises 0.01 ("thin" to tall), the +X side swells 0.01 out."""
    up = np.where(pos[:, 1:2] > 0, [0.0, 0.01, 0.0], 0.0)
    side = np.where(pos[:, 0:1] > 0, [0.01, 0.0, 0.0], 0.0)
    return [up, side]


def animated_morph_cube(path: Path, *, interpolation: str = "LINEAR", times=(0.0, 1 / 30, 2 / 30),
                        weights=((0.0, 0.0), (1.0, 0.0), (1.0, 1.0)), scale: float = 100.0,
                        light: bool = True) -> Path:
    """An AnimatedMorphCube-like file: the cube on a node scaled ``scale``x with two morph targets
    (positions; normals unchanged) whose weights are animated through ``weights`` at ``times``,
    nothing else animated. A floor under it, a light and a camera (``light``) make it renderable."""
    b = GltfBuilder()
    grey = b.add_material("grey", (0.6, 0.6, 0.6))
    blue = b.add_material("blue", (0.3, 0.53, 0.8))
    pos, nrm, idx = cube_mesh()
    mesh = b.add_mesh("cube", pos, idx, material=blue, normals=nrm)
    b.add_morph_targets(mesh, 0, morph_targets(pos), normals=[np.zeros_like(pos)] * 2, weights=[0.0, 0.0])
    node = b.add_node("AnimatedMorphCube", mesh, scale=(scale,) * 3, translation=(0, scale * 0.01, 0))
    keys = np.asarray(weights, float)
    if interpolation == "CUBICSPLINE":
        keys = np.stack([np.zeros_like(keys), keys, np.zeros_like(keys)], axis=1)
    b.add_animation("morph", node, "weights", list(times), keys, interpolation)
    if light:
        s = scale * 0.01
        floor = np.array([[-4, 0, -4], [4, 0, -4], [4, 0, 4], [-4, 0, 4]], float) * s
        b.add_node("floor", b.add_mesh("floor", floor, np.array([0, 2, 1, 0, 3, 2]), material=grey))
        b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 40.0 * s * s), translation=(2 * s, 5 * s, 4 * s))
        cam = b.add_camera("cam", yfov=0.8, znear=0.01 * s)
        b.add_node("cam", camera=cam, translation=(3.5 * s, 4 * s, 8 * s), rotation=_look_rotation(3.5, 3, 8))
    return b.write(path)


def _look_rotation(x: float, y: float, z: float) -> list[float]:
    """Quaternion turning -Z towards the origin from (x, y, z) with +Y up (yaw, then pitch)."""
    yaw = np.arctan2(x, z)
    pitch = -np.arctan2(y, np.hypot(x, z))
    qy = np.array([0, np.sin(yaw / 2), 0, np.cos(yaw / 2)])
    qx = np.array([np.sin(pitch / 2), 0, 0, np.cos(pitch / 2)])
    # qy * qx (Hamilton product, x y z w)
    x1, y1, z1, w1 = qy
    x2, y2, z2, w2 = qx
    return [w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2, w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2, w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2]


if __name__ == "__main__":
    out = Path(sys.argv[1] if len(sys.argv) > 1 else ".")
    out.mkdir(parents=True, exist_ok=True)
    print(rigged_simple(out / "RiggedSimple-like.glb"))
    print(animated_morph_cube(out / "AnimatedMorphCube-like.glb"))
