"""Which faces of a surface photons see: glTF ``doubleSided`` false means a surface has no back
(docs/05-estimators.md §1.8). Used by emission (a directional light's projection map keeps only
cells whose first hit can take a photon) and by tracing (hits on a back are absorbed)."""
from __future__ import annotations

import numpy as np

from pipeline.scene import FrameState


def one_sided_triangles(state: FrameState) -> np.ndarray | None:
    """(F,) bool: the triangles of single-sided materials, None when every material is double-sided."""
    single = np.array([not m.double_sided for m in state.materials], bool)
    if not single.any():
        return None
    return single[state.triangle_material]


def absorb_back_hits(tri: np.ndarray, dirs: np.ndarray, normals: np.ndarray,
                     one_sided: np.ndarray | None) -> np.ndarray:
    """``tri`` with the hits on the back face of a single-sided triangle turned into misses (-1).

    The back is where the ray travels along the geometric normal (``normals`` (F, 3), the sidedness
    the bounce kernel uses). Why: such a surface has no back (glTF ``doubleSided`` false), and an
    element holds one irradiance for both of its faces, so light recorded on the back of a sheet
    that models a wall or roof from inside would show on its inner face (a light leak)."""
    if one_sided is None or not len(tri):
        return tri
    t = np.maximum(tri, 0)
    facing = np.einsum("ij,ij->i", np.take(normals, t, axis=0), np.asarray(dirs, np.float64))
    return np.where((tri >= 0) & np.take(one_sided, t) & (facing > 0.0), -1, tri).astype(tri.dtype, copy=False)
