"""Alpha-masked surfaces (glTF ``alphaMode`` MASK: leaves, fences, hair cards): rays pass where the
surface's alpha is below its ``alphaCutoff`` (glTF 2.0 §3.9.4), as if nothing were there.

Alpha is ``baseColorFactor``'s fourth value times the base-colour texture's alpha channel at the
hit (vertex colours' alpha is not read). :class:`Cutouts` answers, for hits of one frame state,
which fall in a hole; the ray caster (pipeline/photons/raycast.py) continues such rays past the
hole, for photons, camera rays and shadow rays alike. An element of a masked surface gathers photons
only on its solid part, so its area counts only that part (:func:`element_coverage`, sampled once
per element from the texture): the irradiance of a leaf is that of its solid texels, not diluted
by its holes. ``BLEND`` surfaces are rendered opaque.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from .shading import interpolate
from .textures import sample

if TYPE_CHECKING:
    from .materials import Material
    from .scene import FrameState

MASK = "MASK"


def _alpha_texture(material: Material):
    tex = material.base_color_texture
    if tex is None or tex.alpha is None:
        return None
    return replace(tex, image=tex.alpha[:, :, None])


class Cutouts:
    """Which hits of a frame state fall in a masked surface's holes."""

    def __init__(self, materials: list[Material], triangle_material: np.ndarray, texcoords: dict):
        self.tri_mat = np.asarray(triangle_material, np.int64)
        self.masked = {j: (m.base_alpha, m.alpha_cutoff, _alpha_texture(m)) for j, m in enumerate(materials)
                       if m.alpha_mode == MASK}
        self.texcoords = texcoords
        flags = np.zeros(len(materials), bool)
        flags[list(self.masked)] = True
        self.masked_triangle = flags[self.tri_mat] if len(self.tri_mat) else np.zeros(0, bool)

    @classmethod
    def of(cls, state: FrameState) -> "Cutouts | None":
        """The state's cutouts, None when no surface it draws is masked (rays need no second look)."""
        if not any(m.alpha_mode == MASK for m in state.materials):
            return None
        corners = getattr(state, "corners", None)
        found = cls(state.materials, state.triangle_material, corners.texcoords if corners is not None else {})
        return found if found.masked_triangle.any() else None

    def holes(self, tri: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(n,) bool: hits (``tri`` -1 for a miss) whose alpha is below their material's cut-off."""
        tri = np.asarray(tri)
        out = np.zeros(len(tri), bool)
        candidates = np.flatnonzero((tri >= 0) & self.masked_triangle[np.maximum(tri, 0)])
        if not len(candidates):
            return out
        m = self.tri_mat[tri[candidates]]
        for j, (factor, cutoff, tex) in self.masked.items():
            rows = candidates[m == j]
            if not len(rows):
                continue
            alpha = np.full(len(rows), factor)
            if tex is not None:
                corners = self.texcoords.get(tex.texcoord)
                uv = (np.zeros((len(rows), 2)) if corners is None else
                      interpolate(np.take(corners, tri[rows], axis=0).astype(np.float64),
                                  np.asarray(u, np.float64)[rows], np.asarray(v, np.float64)[rows]))
                alpha = alpha * sample(tex, uv)[:, 0]
            out[rows] = alpha < cutoff
        return out


# Points per element whose alpha gives its coverage (a 4 x 4 stratified pattern)
COVERAGE_POINTS = 16


def element_coverage(cutouts: Cutouts | None, triangle_n: np.ndarray, triangle_offset: np.ndarray,
                     cells: Callable[[int], tuple[np.ndarray, np.ndarray]]) -> np.ndarray | None:
    """(E,) the solid fraction of each element (1 off masked surfaces), from the alpha at
    COVERAGE_POINTS points spread over it; None without cutouts. ``cells(n)`` gives the lattice
    points and the cells of a triangle split n x n (pipeline/scene/elements.py)."""
    if cutouts is None or not cutouts.masked_triangle.any():
        return None
    coverage = np.ones(int(triangle_offset[-1]))
    k = int(round(np.sqrt(COVERAGE_POINTS)))
    g = (np.arange(k) + 0.5) / k
    su, w = np.sqrt(np.repeat(g, k)), np.tile(g, k)
    b1, b2 = su * (1.0 - w), su * w  # area-uniform points of a triangle (pbrt's mapping), cell centres
    masked = np.flatnonzero(cutouts.masked_triangle)
    for n in np.unique(triangle_n[masked]):
        tris = masked[triangle_n[masked] == n]
        pts, cell = cells(int(n))
        lattice = pts[cell] / n  # (n*n, 3 corners, 2): the elements' corners as weights of corners 1 and 2
        at = lattice[:, 0, None] + b1[None, :, None] * (lattice[:, 1, None] - lattice[:, 0, None]) \
            + b2[None, :, None] * (lattice[:, 2, None] - lattice[:, 0, None])  # (n*n, points, 2)
        tri = np.repeat(tris, at.shape[0] * at.shape[1])
        uv = np.tile(at.reshape(-1, 2), (len(tris), 1))
        solid = ~cutouts.holes(tri, uv[:, 0], uv[:, 1])
        rows = (triangle_offset[tris][:, None] + np.arange(n * n)[None, :]).ravel()
        coverage[rows] = solid.reshape(len(tris) * n * n, -1).mean(axis=1)
    return coverage
