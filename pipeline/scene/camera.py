"""A camera placed by a (possibly animated) node: looks down its -Z with +Y up (glTF). A pinhole
(perspective: ``yfov``) or orthographic (``ymag``: parallel rays through a view ``2 ymag`` high)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CameraDef:
    name: str
    yfov: float  # vertical field of view, radians
    znear: float
    zfar: float | None
    aspect: float | None  # the file's; the output resolution decides the rendered aspect
    ymag: float | None = None  # orthographic: half the view's height in world units (glTF ymag); None: a pinhole

    @property
    def orthographic(self) -> bool:
        return self.ymag is not None


@dataclass(frozen=True)
class Camera:
    """A camera at one instant: ``to_world`` is its node's world matrix (4x4)."""

    definition: CameraDef
    node: int
    to_world: np.ndarray

    @property
    def position(self) -> np.ndarray:
        return self.to_world[:3, 3].copy()

    @property
    def forward(self) -> np.ndarray:
        f = -self.to_world[:3, 2]
        return f / np.linalg.norm(f)

    @property
    def up(self) -> np.ndarray:
        u = self.to_world[:3, 1]
        return u / np.linalg.norm(u)

    @property
    def world_to_camera(self) -> np.ndarray:
        return np.linalg.inv(self.to_world)


AUTO = "auto"  # the --camera value, and the camera's name (pipeline/scene/default_camera.py)


@dataclass(frozen=True)
class Framing:
    """The auto camera and the animation bounds it frames."""

    camera: Camera
    lo: np.ndarray
    hi: np.ndarray
