"""Surfaces with alpha (glTF ``alphaMode``, §3.9.4): rays pass where the surface is not there.

* MASK (leaves, fences, hair cards): a hit whose alpha is below the ``alphaCutoff`` is a hole.
* BLEND (glass panes, veils, fading objects): a hit is a hole with probability 1 - alpha, decided
  by a uniform number hashed from the ray itself (:func:`ray_uniforms`: its origin, direction and
  the surface it met, so the same ray decides alike on every worker and in every run). A surface of
  alpha a then stops a of the photons, shadow rays and camera samples that reach it and lets the
  rest through: alpha compositing's "over" in expectation (Enderton et al., "Stochastic
  transparency", I3D 2010), for light as for pixels, the pixels' samples averaging it.

Alpha is ``baseColorFactor``'s fourth value times the base-colour texture's alpha channel times
``COLOR_0``'s alpha (a VEC4 colour), at the hit. :class:`Cutouts` answers, for hits of one frame state,
which fall in a hole; the ray caster (pipeline/photons/raycast.py) continues such rays past the
hole, for photons, camera rays and shadow rays alike. An element of such a surface gathers photons
only where they stop, so its area counts only that part (:func:`element_coverage`, sampled once
per element from the texture: the solid fraction of a mask, the mean alpha of a blend): the
irradiance of a leaf is that of its solid texels, not diluted by its holes, and a pane of alpha
0.3 has the irradiance of the light that falls on it.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from .shading import interpolate, texel_at

if TYPE_CHECKING:
    from .materials import Material
    from .scene import FrameState
    from .shading import CornerAttributes

MASK, BLEND = "MASK", "BLEND"
SEE_THROUGH = (MASK, BLEND)  # the alpha modes that let rays through


def _alpha_texture(material: Material):
    tex = material.base_color_texture
    if tex is None or tex.alpha is None:
        return None
    return replace(tex, image=tex.alpha[:, :, None])


def lets_through(material: Material) -> bool:
    """Whether rays may pass some hits of ``material``: a mask, a blend or thin-walled transmission
    (a solid dielectric refracts instead: kernels/scatter.py)."""
    return material.alpha_mode in SEE_THROUGH or (material.transmission > 0 and material.kind != "dielectric")


@dataclass(frozen=True)
class _Passage:
    """How one material lets rays through (see the module docstring)."""

    alpha: float  # baseColorFactor's alpha
    alpha_texture: object  # the base-colour texture's alpha as a one-channel Texture, or None
    cutoff: float | None  # a mask's cut-off; None: not a mask
    blend: bool
    transmission: float  # 0: none
    transmission_texture: object  # a Texture whose R scales ``transmission``, or None
    f0: float  # Fresnel reflectance at normal incidence

    @property
    def random(self) -> bool:
        return self.blend or self.transmission > 0


class Cutouts:
    """Which hits of a frame state fall in a hole of a masked, blended or transmissive surface."""

    def __init__(self, materials: list[Material], triangle_material: np.ndarray, corners: CornerAttributes | None):
        self.tri_mat = np.asarray(triangle_material, np.int64)
        self.masked = {j: _Passage(m.base_alpha, _alpha_texture(m), m.alpha_cutoff if m.alpha_mode == MASK else None,
                                   m.alpha_mode == BLEND, m.transmission if m.kind != "dielectric" else 0.0,
                                   m.transmission_texture, m.f0)
                       for j, m in enumerate(materials) if lets_through(m)}
        self.texcoords = corners.texcoords if corners is not None else {}
        self.vertex_alpha = corners.alpha if corners is not None else None  # (F, 3) or None
        flags = np.zeros(len(materials), bool)
        flags[list(self.masked)] = True
        self.masked_triangle = flags[self.tri_mat] if len(self.tri_mat) else np.zeros(0, bool)

    @classmethod
    def of(cls, state: FrameState) -> "Cutouts | None":
        """The state's cutouts, None when no surface it draws lets rays through (they need no second look)."""
        if not any(lets_through(m) for m in state.materials):
            return None
        found = cls(state.materials, state.triangle_material, getattr(state, "corners", None))
        return found if found.masked_triangle.any() else None

    @property
    def blends(self) -> bool:
        """Some surface's holes are random (a blend, transmission): ``holes`` needs ``uniforms`` and ``cosines``."""
        return any(p.random for p in self.masked.values())

    def holes(self, tri: np.ndarray, u: np.ndarray, v: np.ndarray, uniforms: np.ndarray | None = None,
              cosines: np.ndarray | None = None) -> np.ndarray:
        """(n,) bool: hits (``tri`` -1 for a miss) in a hole: alpha below a mask's cut-off, or the
        hit's ``uniforms`` value in [0, 1) (:func:`ray_uniforms`) at or above the share of rays it
        stops, ``alpha`` on a blend times ``1 - transmission x (1 - F)`` with F Schlick's at the
        ray's |cos| to the surface ``cosines``; both may be None where :attr:`blends` is False."""
        tri = np.asarray(tri)
        out = np.zeros(len(tri), bool)
        candidates = np.flatnonzero((tri >= 0) & self.masked_triangle[np.maximum(tri, 0)])
        if not len(candidates):
            return out
        m = self.tri_mat[tri[candidates]]
        for j, passage in self.masked.items():
            rows = candidates[m == j]
            if not len(rows):
                continue
            hole, stops = self._stops(passage, tri[rows], np.asarray(u, np.float64)[rows],
                                      np.asarray(v, np.float64)[rows], None if cosines is None else cosines[rows])
            if passage.random:
                hole |= uniforms[rows] >= stops
            out[rows] = hole
        return out

    def coverage(self, tri: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(n,) the share of rays arriving along the normal that each hit point stops: 0 in a mask's
        holes, alpha on a blend, 1 - transmission x (1 - F0) on a transmissive surface, 1 elsewhere."""
        tri = np.asarray(tri)
        out = np.ones(len(tri))
        m = self.tri_mat[tri]
        for j, passage in self.masked.items():
            rows = np.flatnonzero(m == j)
            if len(rows):
                hole, stops = self._stops(passage, tri[rows], np.asarray(u, np.float64)[rows],
                                          np.asarray(v, np.float64)[rows], np.ones(len(rows)))
                out[rows] = np.where(hole, 0.0, stops)
        return out

    def _stops(self, passage: _Passage, tri: np.ndarray, u: np.ndarray, v: np.ndarray,
               cosines: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """(a mask's holes, the share of the other rays stopped) at hits of a material's triangles."""
        alpha = np.full(len(tri), passage.alpha)
        if passage.alpha_texture is not None:
            alpha = alpha * texel_at(self.texcoords, passage.alpha_texture, tri, u, v)[:, 0]
        if self.vertex_alpha is not None:
            corners = np.take(self.vertex_alpha, tri, axis=0)[:, :, None].astype(np.float64)
            alpha = alpha * interpolate(corners, u, v)[:, 0]
        hole = alpha < passage.cutoff if passage.cutoff is not None else np.zeros(len(tri), bool)
        stops = np.clip(alpha, 0.0, 1.0) if passage.blend else np.ones(len(tri))
        if passage.transmission > 0:
            t = np.full(len(tri), passage.transmission)
            if passage.transmission_texture is not None:
                t = t * texel_at(self.texcoords, passage.transmission_texture, tri, u, v)[:, 0]
            fresnel = passage.f0 + (1.0 - passage.f0) * (1.0 - np.clip(cosines, 0.0, 1.0)) ** 5  # Schlick 1994
            stops = stops * (1.0 - t * (1.0 - fresnel))
        return hole, stops



_GOLDEN, _MIX1, _MIX2 = np.uint64(0x9E3779B97F4A7C15), np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)


def ray_uniforms(origins: np.ndarray, directions: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """(n,) float64 in [0, 1): a hash of each ray's float32 origin and direction bits and the
    triangle it met (SplitMix64's finaliser, Steele et al. 2014, over the seven words in turn), so a
    blend's hole depends on nothing but the ray: the same on any worker, in any run."""
    words = np.concatenate([np.ascontiguousarray(origins, np.float32).view(np.uint32).reshape(len(tri), 3),
                            np.ascontiguousarray(directions, np.float32).view(np.uint32).reshape(len(tri), 3),
                            np.asarray(tri).astype(np.int64).astype(np.uint32)[:, None]], axis=1).astype(np.uint64)
    h = np.zeros(len(tri), np.uint64)
    for k in range(words.shape[1]):
        h = h ^ words[:, k]
        h = h + _GOLDEN
        h = (h ^ (h >> np.uint64(30))) * _MIX1
        h = (h ^ (h >> np.uint64(27))) * _MIX2
        h = h ^ (h >> np.uint64(31))
    return (h >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))


# Points per element whose alpha gives its coverage (a 4 x 4 stratified pattern)
COVERAGE_POINTS = 16


def element_coverage(cutouts: Cutouts | None, triangle_n: np.ndarray, triangle_offset: np.ndarray,
                     cells: Callable[[int], tuple[np.ndarray, np.ndarray]]) -> np.ndarray | None:
    """(E,) the share of the photons reaching each element that stop on it (1 off masked and blended
    surfaces): the mean :meth:`Cutouts.coverage` of COVERAGE_POINTS points spread over it; None
    without cutouts. ``cells(n)`` gives the lattice
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
        solid = cutouts.coverage(tri, uv[:, 0], uv[:, 1])
        rows = (triangle_offset[tris][:, None] + np.arange(n * n)[None, :]).ravel()
        coverage[rows] = solid.reshape(len(tris) * n * n, -1).mean(axis=1)
    return coverage
