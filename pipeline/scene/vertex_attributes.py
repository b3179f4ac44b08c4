"""A primitive's vertex attributes beyond POSITION: ``NORMAL``, ``TEXCOORD_0``/``_1``, ``COLOR_0``.

Read and checked here (one-line errors naming the accessor) so that the loader only attaches them to
its mesh instances. Normals stay in the mesh's local space (pipeline/scene/shading.py turns them into
world space per pose); texture coordinates and colours do not move with the animation.
Spec: glTF 2.0 §3.7.2.1 (attribute types and normalized integer colours and texture coordinates).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .gltf import GltfDocument

if TYPE_CHECKING:
    import pygltflib

TEXCOORD_SETS = (0, 1)


@dataclass(frozen=True, eq=False)
class VertexAttributes:
    """Optional per-vertex data of one primitive, one row per POSITION."""

    normals: np.ndarray | None  # (V, 3) float64 local, unit or zero (zero: flat there)
    texcoords: dict[int, np.ndarray]  # set -> (V, 2) float32
    color: np.ndarray | None  # (V, 3) float32 linear RGB
    alpha: np.ndarray | None = None  # (V,) float32 COLOR_0's alpha (a VEC4 with some value below 1), else None
    tangents: np.ndarray | None = None  # (V, 4) float64 TANGENT: unit xyz (zero: none there), w the handedness +-1

    @property
    def empty(self) -> bool:
        return self.normals is None and not self.texcoords and self.color is None


def read_vertex_attributes(doc: GltfDocument, attributes: pygltflib.Attributes, n_vertices: int,
                           field: str) -> VertexAttributes:
    """NORMAL, TANGENT, TEXCOORD_0/1 and COLOR_0 of a primitive's ``attributes`` (pygltflib), checked."""

    def read(name: str, widths: tuple[int, ...]) -> np.ndarray | None:
        index = getattr(attributes, name, None)
        if index is None:
            return None
        where = f"{field}.attributes.{name}"
        data = np.asarray(doc.accessor(index, where), dtype=np.float64)
        if data.ndim != 2 or data.shape[1] not in widths:
            raise doc.error(f"must be {' or '.join(f'VEC{w}' for w in widths)}", where)
        if len(data) != n_vertices:
            raise doc.error(f"has {len(data)} entries for {n_vertices} positions", where)
        if not np.all(np.isfinite(data)):
            bad = int(np.flatnonzero(~np.isfinite(data).all(1))[0])
            raise doc.error(f"entry {bad} is NaN or Inf", where)
        return data

    normals = read("NORMAL", (3,))
    if normals is not None:
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        normals = np.divide(normals, length, out=np.zeros_like(normals), where=length > 1e-12)
    texcoords = {}
    for s in TEXCOORD_SETS:
        uv = read(f"TEXCOORD_{s}", (2,))
        if uv is not None:
            texcoords[s] = uv.astype(np.float32)
    tangents = read("TANGENT", (4,))
    if tangents is not None and normals is not None:  # a tangent frame needs the normal it is tangent to
        length = np.linalg.norm(tangents[:, :3], axis=1, keepdims=True)
        xyz = np.divide(tangents[:, :3], length, out=np.zeros((len(tangents), 3)), where=length > 1e-12)
        tangents = np.c_[xyz, np.where(tangents[:, 3] < 0, -1.0, 1.0)]
    else:
        tangents = None
    color = read("COLOR_0", (3, 4))
    alpha = None
    if color is not None:
        if color.shape[1] == 4 and np.any(color[:, 3] < 1):  # multiplies the base colour's alpha (glTF §3.9.2)
            alpha = np.clip(color[:, 3], 0.0, 1.0).astype(np.float32)
        color = np.clip(color[:, :3], 0.0, 1.0).astype(np.float32)
    return VertexAttributes(normals, texcoords, color, alpha, tangents)
