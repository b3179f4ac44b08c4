"""The file's node hierarchy and the mesh instances it places, as the loader reads them (rest
coordinates; pipeline/scene/scene.py poses them)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .animation import Deformation
from .vertex_attributes import VertexAttributes


@dataclass(frozen=True)
class Node:
    index: int
    name: str
    parent: int | None
    children: tuple[int, ...]
    translation: np.ndarray
    rotation: np.ndarray  # quaternion x, y, z, w
    scale: np.ndarray
    matrix: np.ndarray | None  # a static matrix given instead of TRS
    mesh: int | None
    camera: int | None
    light: int | None
    visible: bool = True  # KHR_node_visibility's ``visible`` as the file gives it (pipeline/scene/visibility.py)


@dataclass(frozen=True)
class MeshInstance:
    """One primitive of a mesh placed by a node, in the mesh's local coordinates."""

    index: int
    node: int
    mesh: int
    primitive: int
    name: str
    vertices: np.ndarray  # (V, 3) float64, local
    faces: np.ndarray  # (F, 3) int64, zero-area triangles removed
    material: int  # index into Scene.materials
    source_faces: np.ndarray  # (F,) int64: index of each kept triangle in the primitive
    attributes: VertexAttributes | None = None  # NORMAL, TEXCOORD_n, COLOR_0 (vertex_attributes.py)
    deformation: Deformation | None = None  # a skin and/or morph targets (animation.py): posed per vertex
