"""glTF animation: samplers (STEP, LINEAR with slerp for rotations, CUBICSPLINE, clamped outside
keys) and the skins and morph targets they pose, as pure functions over arrays.

Interpolation follows the glTF 2.0 specification, Appendix C ("Animation Sampler Interpolation
Modes"). Quaternions are (x, y, z, w) as glTF stores them.

Morph targets (glTF 2.0 §3.7.2.2 "Morph Targets"): a target holds displacements of POSITION and
NORMAL; the morphed attribute is ``base + sum_k w_k * target_k``, with the weights from the node's
animated ``weights`` channel, else ``node.weights``, else ``mesh.weights``, else zeros.

Skins (glTF 2.0 §3.7.3 "Skins"): each vertex is moved by up to 4 x (number of JOINTS_n/WEIGHTS_n
sets) joints, ``p' = sum_i w_i * jointMatrix_i * p`` with ``jointMatrix_i = globalTransform(joint_i)
* inverseBindMatrix_i`` taken straight to world space (the spec's ``inverse(globalTransform(meshNode))``
factor cancels against the mesh node's own transform, which "MUST be ignored" for a skinned mesh).
Normals move by the inverse transpose of the blended matrix (§3.7.3.3), here its cofactor matrix
times the sign of its determinant (the same direction, defined even where the matrix is singular).
Morphing comes first, then skinning (§3.7.2.2).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

INTERPOLATIONS = ("LINEAR", "STEP", "CUBICSPLINE")
PATHS = ("translation", "rotation", "scale")  # node paths; "weights" drives morph targets


@dataclass(frozen=True)
class Sampler:
    """One animation channel's keyframes: ``times`` (k,), ``values`` (k, w) or (k, 3, w) for cubic."""

    times: np.ndarray
    values: np.ndarray
    interpolation: str
    path: str

    @property
    def start(self) -> float:
        return float(self.times[0])

    @property
    def end(self) -> float:
        return float(self.times[-1])

    def evaluate(self, t: float) -> np.ndarray:
        """The channel's value at time ``t`` seconds (clamped to the key range)."""
        times = self.times
        cubic = self.interpolation == "CUBICSPLINE"
        keys = self.values[:, 1] if cubic else self.values
        if t <= times[0] or len(times) == 1:
            return self._finish(keys[0])
        if t >= times[-1]:
            return self._finish(keys[-1])
        k = int(np.searchsorted(times, t, side="right")) - 1
        t0, t1 = times[k], times[k + 1]
        dt = t1 - t0
        s = (t - t0) / dt
        if self.interpolation == "STEP":
            return self._finish(keys[k])
        if cubic:
            # Hermite spline, glTF 2.0 Appendix C: p(s) with out-tangent b_k and in-tangent a_{k+1}
            v0, b0 = self.values[k, 1], self.values[k, 2]
            v1, a1 = self.values[k + 1, 1], self.values[k + 1, 0]
            s2, s3 = s * s, s * s * s
            value = (
                (2 * s3 - 3 * s2 + 1) * v0
                + dt * (s3 - 2 * s2 + s) * b0
                + (-2 * s3 + 3 * s2) * v1
                + dt * (s3 - s2) * a1
            )
            return self._finish(value)
        if self.path == "rotation":
            return slerp(keys[k], keys[k + 1], s)
        return keys[k] + (keys[k + 1] - keys[k]) * s

    def _finish(self, value: np.ndarray) -> np.ndarray:
        if self.path == "rotation":
            n = np.linalg.norm(value)
            return value / n if n > 0 else np.array([0.0, 0.0, 0.0, 1.0])
        return np.array(value, dtype=np.float64)


def slerp(q0: np.ndarray, q1: np.ndarray, s: float) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions along the shorter arc."""
    q0 = q0 / np.linalg.norm(q0)
    q1 = q1 / np.linalg.norm(q1)
    d = float(np.dot(q0, q1))
    if d < 0.0:
        q1, d = -q1, -d
    if d > 0.9995:  # nearly parallel: lerp is exact to float precision and avoids 0/0
        q = q0 + (q1 - q0) * s
        return q / np.linalg.norm(q)
    theta = np.arccos(d)
    sin_theta = np.sin(theta)
    return (np.sin((1 - s) * theta) * q0 + np.sin(s * theta) * q1) / sin_theta


def quaternion_matrix(q: np.ndarray) -> np.ndarray:
    """3x3 rotation matrix of a unit quaternion (x, y, z, w); (..., 3, 3) of quaternions (..., 4)."""
    q = np.asarray(q, dtype=np.float64)
    unit = q / np.linalg.norm(q) if q.ndim == 1 else q / np.linalg.norm(q, axis=-1, keepdims=True)  # same bits as ever
    x, y, z, w = np.moveaxis(unit, -1, 0)
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    return np.stack([np.stack(row, axis=-1) for row in rows], axis=-2)


def trs_matrix(t: np.ndarray, r: np.ndarray, s: np.ndarray) -> np.ndarray:
    """4x4 matrix T * R * S, the glTF node transform (spec §3.5.3)."""
    m = np.eye(4)
    m[:3, :3] = quaternion_matrix(r) * np.asarray(s, dtype=np.float64)[None, :]
    m[:3, 3] = t
    return m


# --- skins and morph targets ---------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Skin:
    """A glTF skin: its joints (node indices) and their inverse bind matrices (J, 4, 4), row-major."""

    index: int
    joints: tuple[int, ...]
    inverse_bind: np.ndarray


@dataclass(frozen=True, eq=False)
class Deformation:
    """How one mesh instance deforms: morph targets, a skin, or both (one row per POSITION)."""

    target_positions: np.ndarray | None = None  # (K, V, 3) float64 displacements
    target_normals: np.ndarray | None = None  # (K, V, 3) float64 displacements
    target_tangents: np.ndarray | None = None  # (K, V, 3) float64 displacements of TANGENT's xyz
    default_weights: np.ndarray | None = None  # (K,) node.weights, else mesh.weights, else zeros
    skin: Skin | None = None
    joints: np.ndarray | None = None  # (V, S) int64 into skin.joints, S = 4 x the JOINTS_n sets
    weights: np.ndarray | None = None  # (V, S) float64, rows normalised to sum 1 (or all zero)

    @property
    def n_targets(self) -> int:
        return 0 if self.default_weights is None else len(self.default_weights)


def morph(base: np.ndarray, targets: np.ndarray | None, weights: np.ndarray) -> np.ndarray:
    """(V, 3) ``base + sum_k weights[k] * targets[k]`` (glTF 2.0 §3.7.2.2); ``base`` when no targets."""
    if targets is None or not len(weights):
        return np.asarray(base, np.float64)
    return np.asarray(base, np.float64) + np.tensordot(np.asarray(weights, np.float64), targets, axes=1)


def joint_matrices(joint_world: np.ndarray, inverse_bind: np.ndarray) -> np.ndarray:
    """(J, 4, 4) ``globalTransform(joint_j) @ inverseBindMatrix_j``: bind space to world (glTF §3.7.3)."""
    return np.einsum("jab,jbc->jac", joint_world, inverse_bind)


def blend(joints: np.ndarray, weights: np.ndarray, matrices: np.ndarray) -> np.ndarray:
    """(V, 4, 4) per-vertex skinning matrix ``sum_i weights[v, i] * matrices[joints[v, i]]``."""
    return np.einsum("vs,vsab->vab", weights, matrices[joints])


def skin_points(points: np.ndarray, blended: np.ndarray) -> np.ndarray:
    """(V, 3) world positions of bind-space ``points`` under per-vertex matrices ``blended`` (V, 4, 4)."""
    return np.einsum("vab,vb->va", blended[:, :3, :3], points) + blended[:, :3, 3]


def transform_normals(normals: np.ndarray, linear: np.ndarray) -> np.ndarray:
    """(V, 3) unit normals carried by the inverse transpose of ``linear`` ((V, 3, 3) or (3, 3)):
    the cofactor matrix times sign(det), renormalised; zero where a normal or matrix vanishes."""
    m = np.broadcast_to(linear, (len(normals), 3, 3))
    c0, c1, c2 = m[:, :, 0], m[:, :, 1], m[:, :, 2]
    cofactor = np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=2)
    det = np.einsum("vi,vi->v", c0, cofactor[:, :, 0])
    n = np.einsum("vab,vb->va", cofactor, normals) * np.where(det < 0, -1.0, 1.0)[:, None]
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 1e-12)


def transform_tangents(tangents: np.ndarray, linear: np.ndarray) -> np.ndarray:
    """(V, 4) unit tangents (xyz) carried by ``linear`` ((V, 3, 3) or (3, 3)), as vectors in the
    surface are, renormalised (zero where one vanishes), with the handedness w times sign(det):
    a mirroring matrix reverses the bitangent ``w (n x t)`` that glTF 2.0 §3.7.2.1 defines."""
    m = np.broadcast_to(linear, (len(tangents), 3, 3))
    t = np.einsum("vab,vb->va", m, tangents[:, :3])
    length = np.linalg.norm(t, axis=1, keepdims=True)
    t = np.divide(t, length, out=np.zeros_like(t), where=length > 1e-12)
    return np.c_[t, tangents[:, 3] * np.where(np.linalg.det(m) < 0, -1.0, 1.0)]


def pose_tangents(tangents: np.ndarray, deformation: Deformation, morph_weights: np.ndarray | None,
                  node_world: np.ndarray, joint_world: np.ndarray | None) -> np.ndarray:
    """(V, 4) world tangents of one deforming instance, as :func:`pose_vertices` poses its normals:
    morphed by TANGENT's target displacements, then carried by its node's or its skin's matrices."""
    d = deformation
    w = morph_weights if morph_weights is not None else np.zeros(0)
    local = np.c_[morph(tangents[:, :3], d.target_tangents, w), tangents[:, 3]]
    if d.skin is None:
        return transform_tangents(local, node_world[:3, :3])
    blended = blend(d.joints, d.weights, joint_matrices(joint_world, d.skin.inverse_bind))
    blended[d.weights.sum(axis=1) == 0] = node_world
    return transform_tangents(local, blended[:, :3, :3])


def normalise_weights(weights: np.ndarray) -> np.ndarray:
    """Skin weights with each row scaled to sum 1 (glTF §3.7.3.1 asks for it; exporters round);
    all-zero rows stay zero (such a vertex follows its node, see :func:`pose_vertices`)."""
    total = weights.sum(axis=1, keepdims=True)
    return np.divide(weights, total, out=np.zeros_like(weights), where=total > 0)


def pose_vertices(base: np.ndarray, normals: np.ndarray | None, deformation: Deformation,
                  morph_weights: np.ndarray | None, node_world: np.ndarray,
                  joint_world: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
    """World positions (V, 3) and unit normals (V, 3) or None of one deforming instance.

    ``morph_weights`` (K,) are the instance's weights at this instant; ``node_world`` is its node's
    world matrix (used only without a skin); ``joint_world`` (J, 4, 4) its skin's joints' world
    matrices."""
    d = deformation
    w = morph_weights if morph_weights is not None else np.zeros(0)
    local = morph(base, d.target_positions, w)
    local_n = None
    if normals is not None:
        local_n = morph(normals, d.target_normals, w)
    if d.skin is None:
        points = local @ node_world[:3, :3].T + node_world[:3, 3]
        return points, None if local_n is None else transform_normals(local_n, node_world[:3, :3])
    blended = blend(d.joints, d.weights, joint_matrices(joint_world, d.skin.inverse_bind))
    unbound = d.weights.sum(axis=1) == 0  # no joint holds it: it stays where its node puts it
    if unbound.any():
        blended[unbound] = node_world
    points = skin_points(local, blended)
    return points, None if local_n is None else transform_normals(local_n, blended[:, :3, :3])
