"""glTF animation samplers: STEP, LINEAR (slerp for rotations) and CUBICSPLINE, clamped outside keys.

Interpolation follows the glTF 2.0 specification, Appendix C ("Animation Sampler Interpolation
Modes"). Quaternions are (x, y, z, w) as glTF stores them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

INTERPOLATIONS = ("LINEAR", "STEP", "CUBICSPLINE")
PATHS = ("translation", "rotation", "scale")


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
    """3x3 rotation matrix of a unit quaternion (x, y, z, w)."""
    x, y, z, w = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def trs_matrix(t: np.ndarray, r: np.ndarray, s: np.ndarray) -> np.ndarray:
    """4x4 matrix T * R * S, the glTF node transform (spec §3.5.3)."""
    m = np.eye(4)
    m[:3, :3] = quaternion_matrix(r) * np.asarray(s, dtype=np.float64)[None, :]
    m[:3, 3] = t
    return m
