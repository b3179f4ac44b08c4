"""Procedural triangle meshes for the built-in scenes: quads, boxes, stairs, tori, spheres.

Each function returns ``(positions, indices)``: float64 (n, 3) vertices and int (m, 3) triangles
wound counter-clockwise when seen from the side the surface faces (glTF's front face). Quads are
two triangles sharing the diagonal from the first corner, so both get the same subdivision in the
element mesh. Rotations here are xyzw quaternions, as glTF stores them.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

TriangleMesh = tuple[np.ndarray, np.ndarray]


def quad(corner: Sequence[float], edge_u: Sequence[float], edge_v: Sequence[float]) -> TriangleMesh:
    """The parallelogram corner, corner+u, corner+u+v, corner+v, facing along u x v."""
    c, u, v = (np.asarray(a, dtype=np.float64) for a in (corner, edge_u, edge_v))
    positions = np.array([c, c + u, c + u + v, c + v])
    return positions, np.array([[0, 1, 2], [0, 2, 3]])


def merge(parts: Sequence[TriangleMesh]) -> TriangleMesh:
    """One mesh holding all ``parts`` (indices re-based)."""
    positions, indices, base = [], [], 0
    for pos, idx in parts:
        positions.append(np.asarray(pos, dtype=np.float64))
        indices.append(np.asarray(idx).reshape(-1, 3) + base)
        base += len(pos)
    return np.concatenate(positions), np.concatenate(indices)


def box(size: Sequence[float], center: Sequence[float] = (0.0, 0.0, 0.0), inward: bool = False,
        cell: float | None = None) -> TriangleMesh:
    """An axis-aligned box of 6 faces facing outward (or inward, to be seen from inside).

    Each face is one quad, or with ``cell`` a :func:`panel` of cells about that size, which keeps
    long thin faces (slabs, parapets) from becoming slivers that subdivide into many elements.
    """
    sx, sy, sz = (float(s) for s in size)
    lo = np.asarray(center, dtype=np.float64) - 0.5 * np.array([sx, sy, sz])
    X, Y, Z = np.array([sx, 0, 0]), np.array([0, sy, 0]), np.array([0, 0, sz])
    face = quad if cell is None else (lambda c, u, v: panel(c, u, v, cell))
    faces = [
        face(lo, Z, Y),            # -x
        face(lo + X, Y, Z),        # +x
        face(lo, X, Z),            # -y
        face(lo + Y, Z, X),        # +y
        face(lo, Y, X),            # -z
        face(lo + Z, X, Y),        # +z
    ]
    positions, indices = merge(faces)
    if inward:
        indices = indices[:, ::-1]
    return positions, indices


def panel(corner: Sequence[float], edge_u: Sequence[float], edge_v: Sequence[float], cell: float) -> TriangleMesh:
    """The parallelogram of :func:`quad` cut into a grid of cells no longer than ``cell`` on a side."""
    nu = max(1, math.ceil(float(np.linalg.norm(edge_u)) / cell - 1e-9))
    nv = max(1, math.ceil(float(np.linalg.norm(edge_v)) / cell - 1e-9))
    return grid(corner, edge_u, edge_v, nu, nv)


def room_shell(width: float, height: float, depth: float, cell: float | None = None) -> dict[str, TriangleMesh]:
    """The six inner faces of the box [0, width] x [0, height] x [0, depth], each facing into it.

    Keys: ``floor``, ``ceiling``, ``wall_left`` (x = 0), ``wall_right`` (x = width), ``wall_back``
    (z = 0), ``wall_front`` (z = depth). Each is one quad, or a :func:`panel` with ``cell``.
    """
    X, Y, Z = np.array([width, 0.0, 0.0]), np.array([0.0, height, 0.0]), np.array([0.0, 0.0, depth])
    face = quad if cell is None else (lambda c, u, v: panel(c, u, v, cell))
    origin = np.zeros(3)
    return {
        "floor": face(origin, Z, X),
        "ceiling": face(Y, X, Z),
        "wall_left": face(origin, Y, Z),
        "wall_right": face(X, Z, Y),
        "wall_back": face(origin, X, Y),
        "wall_front": face(Z, Y, X),
    }


def grid(corner: Sequence[float], edge_u: Sequence[float], edge_v: Sequence[float], nu: int, nv: int) -> TriangleMesh:
    """The parallelogram of :func:`quad` cut into nu x nv quads (for surfaces wanted finely meshed)."""
    c, u, v = (np.asarray(a, dtype=np.float64) for a in (corner, edge_u, edge_v))
    i, j = np.meshgrid(np.arange(nu + 1), np.arange(nv + 1), indexing="ij")
    positions = c + (i.reshape(-1, 1) / nu) * u + (j.reshape(-1, 1) / nv) * v
    a = (np.arange(nu)[:, None] * (nv + 1) + np.arange(nv)[None, :]).reshape(-1)
    b, d = a + (nv + 1), a + 1
    e = b + 1
    indices = np.concatenate([np.stack([a, b, e], 1), np.stack([a, e, d], 1)])
    return positions, indices


def stairs(steps: int, width: float, rise: float, run: float, origin: Sequence[float] = (0.0, 0.0, 0.0),
           cells_across: int = 1, bottom: bool = True) -> TriangleMesh:
    """A solid straight flight climbing along +z from ``origin`` (front-left-bottom corner), ``width`` along +x.

    Every face is cut into step-sized cells so the flight is made of small triangles: each riser
    (facing -z) and tread (facing +y) is cut ``cells_across`` times across the width, and the sides
    are one column of rise-high cells per step. A grid of the same cells closes the back (under
    the top landing), and one the bottom unless ``bottom`` is False (a flight standing on a floor
    needs none).
    """
    o = np.asarray(origin, dtype=np.float64)
    X, up, ahead = np.array([width, 0.0, 0.0]), np.array([0.0, rise, 0.0]), np.array([0.0, 0.0, run])
    parts = []
    for k in range(steps):
        front = o + k * up + k * ahead
        parts.append(grid(front, up, X, 1, cells_across))                          # riser, faces -z
        parts.append(grid(front + up, ahead, X, 1, cells_across))                  # tread, faces +y
        column = (k + 1) * up
        parts.append(grid(o + k * ahead, ahead, column, 1, k + 1))                 # -x side
        parts.append(grid(o + X + k * ahead, column, ahead, k + 1, 1))             # +x side
    length, height = steps * ahead, steps * up
    parts.append(grid(o + length, X, height, cells_across, steps))                # back, faces +z
    if bottom:
        parts.append(grid(o, X, length, cells_across, steps))                     # bottom, faces -y
    return merge(parts)


def torus(major_radius: float, minor_radius: float, segments: int = 32, sides: int = 12) -> TriangleMesh:
    """A torus around the y axis (the ring lies in the xz plane), facing outward."""
    u = np.linspace(0.0, 2 * math.pi, segments, endpoint=False)
    v = np.linspace(0.0, 2 * math.pi, sides, endpoint=False)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    ring = major_radius + minor_radius * np.cos(vv)
    positions = np.stack([ring * np.cos(uu), minor_radius * np.sin(vv), -ring * np.sin(uu)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(segments), np.arange(sides), indexing="ij")
    a = i * sides + j
    b = ((i + 1) % segments) * sides + j
    c = ((i + 1) % segments) * sides + (j + 1) % sides
    d = i * sides + (j + 1) % sides
    indices = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return positions, indices


def uv_sphere(radius: float, rings: int = 12, segments: int = 24) -> TriangleMesh:
    """A latitude-longitude sphere at the origin, facing outward (single triangles at the poles)."""
    theta = np.linspace(0.0, math.pi, rings + 1)[1:-1]
    phi = np.linspace(0.0, 2 * math.pi, segments, endpoint=False)
    tt, pp = np.meshgrid(theta, phi, indexing="ij")
    body = np.stack([np.sin(tt) * np.cos(pp), np.cos(tt), -np.sin(tt) * np.sin(pp)], -1).reshape(-1, 3)
    positions = radius * np.concatenate([[[0.0, 1.0, 0.0]], body, [[0.0, -1.0, 0.0]]])
    north, south = 0, len(positions) - 1
    ring = lambda r, s: 1 + r * segments + (s % segments)  # noqa: E731 - index of body vertex
    tris = []
    for s in range(segments):
        tris.append([north, ring(0, s), ring(0, s + 1)])
        tris.append([south, ring(rings - 2, s + 1), ring(rings - 2, s)])
        for r in range(rings - 2):
            a, b = ring(r, s), ring(r, s + 1)
            c, d = ring(r + 1, s + 1), ring(r + 1, s)
            tris += [[a, d, c], [a, c, b]]
    return positions, np.array(tris)


def sphere_normals(positions: np.ndarray) -> np.ndarray:
    """Unit outward vertex normals of a sphere centred at the origin (:func:`uv_sphere`), for
    smooth shading (glTF NORMAL)."""
    p = np.asarray(positions, dtype=np.float64)
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def torus_normals(positions: np.ndarray, major_radius: float) -> np.ndarray:
    """Unit outward vertex normals of a :func:`torus` about the y axis: away from the ring's centre line."""
    p = np.asarray(positions, dtype=np.float64)
    radial = p * [1.0, 0.0, 1.0]
    centre = major_radius * radial / np.linalg.norm(radial, axis=1, keepdims=True)
    n = p - centre
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def transformed(mesh: TriangleMesh, rotation: Sequence[float] = (0, 0, 0, 1),
                translation: Sequence[float] = (0, 0, 0), scale: float | Sequence[float] = 1.0) -> TriangleMesh:
    """``mesh`` scaled, rotated (xyzw quaternion) and translated, in that order (glTF's TRS order)."""
    positions, indices = mesh
    m = quaternion_matrix(rotation)
    out = (np.asarray(positions) * np.asarray(scale, dtype=np.float64)) @ m.T + np.asarray(translation)
    if np.prod(np.broadcast_to(np.asarray(scale, dtype=np.float64), 3)) < 0:
        indices = indices[:, ::-1]
    return out, indices


def quaternion_matrix(q: Sequence[float]) -> np.ndarray:
    """The 3x3 rotation matrix of a unit xyzw quaternion."""
    x, y, z, w = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def axis_angle(axis: Sequence[float], angle: float) -> list[float]:
    """The xyzw quaternion rotating by ``angle`` radians about ``axis``."""
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    s = math.sin(angle / 2)
    return [float(a[0] * s), float(a[1] * s), float(a[2] * s), math.cos(angle / 2)]


def multiply_quaternions(q: Sequence[float], r: Sequence[float]) -> list[float]:
    """The xyzw product q * r: the rotation r followed by q."""
    x1, y1, z1, w1 = q
    x2, y2, z2, w2 = r
    return [w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2]


def look_at(eye: Sequence[float], target: Sequence[float], up: Sequence[float] = (0.0, 1.0, 0.0)) -> list[float]:
    """The xyzw rotation that points a node's -Z (camera view, light direction) from ``eye`` at ``target``.

    The node's +Y is kept as close to ``up`` as possible.
    """
    forward = np.asarray(target, dtype=np.float64) - np.asarray(eye, dtype=np.float64)
    forward /= np.linalg.norm(forward)
    up = np.asarray(up, dtype=np.float64)
    if abs(float(np.dot(up / np.linalg.norm(up), forward))) > 0.999:
        up = np.array([0.0, 0.0, -1.0]) if abs(forward[1]) > 0.9 else np.array([0.0, 1.0, 0.0])
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    return matrix_quaternion(np.stack([right, true_up, -forward], axis=1))


def matrix_quaternion(m: np.ndarray) -> list[float]:
    """The unit xyzw quaternion of a 3x3 rotation matrix (Shepperd's method)."""
    m = np.asarray(m, dtype=np.float64)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s]
    q = np.asarray(q)
    q = q / np.linalg.norm(q)
    return [float(v) for v in (q if q[3] >= 0 else -q)]
