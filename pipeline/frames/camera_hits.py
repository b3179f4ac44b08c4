"""The hit records of the compositor's camera paths: one depth's ray hits with their map
irradiance, and their points, normals and mirror directions computed on demand.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from pipeline.scene.shading import triangle_points

if TYPE_CHECKING:
    from .shading_tables import ShadingTables


class CameraHits:
    """One depth's ray hits. Points and normals are computed only for the rows a step asks for
    (None: all rows, cached), so hits no light reaches cost no geometry."""

    def __init__(self, sh: ShadingTables, tri: np.ndarray, u: np.ndarray, v: np.ndarray, origins: np.ndarray,
                 dirs: np.ndarray, t: np.ndarray) -> None:
        self.tri, self.origins, self.dirs = tri, origins, dirs
        self.u, self.v = u, v
        self._surface = sh.surface
        # light-culling cell of every hit, and the map irradiance there: the barycentric blend of the
        # hit element's three vertex irradiances, on PoCL (kernels/surface.cl)
        self.cell, self.indirect = tri, None
        if sh.lookup is not None:
            self.cell, self.indirect = sh.lookup(tri, u, v)
        self.also_indirect = [lookup(tri, u, v)[1] for lookup in sh.also]
        self.t = t.astype(np.float32)
        self.u, self.v = u.astype(np.float32), v.astype(np.float32)
        self._normals, self._corners = sh.normals, sh.corners
        self._cache = {}

    def _full(self, name, make):
        if name not in self._cache:
            self._cache[name] = make(None)
        return self._cache[name]

    def points(self, rows: np.ndarray | None = None) -> np.ndarray:
        """Hit points from the triangle's corners and Embree's barycentrics, not origin + t dir:
        their error follows the hit triangle's own scale, which the ray offsets assume
        (pipeline/photons/raycast.py), however far the ray came."""
        if rows is None:
            return self._full("points", lambda _: self._points(self.tri, self.u, self.v))
        return self._points(np.take(self.tri, rows), np.take(self.u, rows), np.take(self.v, rows))

    def _points(self, tri, u, v) -> np.ndarray:
        return triangle_points(np.take(self._corners, tri, axis=0), u, v)

    def normal(self, rows: np.ndarray | None = None) -> np.ndarray:
        return np.take(self._normals, self.tri if rows is None else self.tri[rows], axis=0)

    def cos_in(self, rows: np.ndarray | None = None) -> np.ndarray:
        """normal . ray direction (negative on the front face)."""
        if rows is None:
            return self._full("cos_in", lambda _: np.einsum("ij,ij->i", self.normal(), self.dirs))
        return np.einsum("ij,ij->i", self.normal(rows), np.take(self.dirs, rows, axis=0))

    def facing(self, rows: np.ndarray | None = None) -> np.ndarray:
        """Unit normals turned towards the viewer (surfaces reflect on both faces)."""
        if rows is None:
            return self._full("facing", lambda _: self._facing(self.normal(), self.cos_in()))
        return self._facing(self.normal(rows), self.cos_in(rows))

    def shading(self, rows: np.ndarray | None = None) -> np.ndarray:
        """Shading normals turned towards the viewer, in the hemisphere :meth:`facing` gives."""
        if not self._surface.smooth:
            return self.facing(rows)
        if rows is None:
            return self._full("shading", lambda _: self._shading(None))
        return self._shading(rows)

    def _shading(self, rows):
        tri, u, v = (self.tri, self.u, self.v) if rows is None else (self.tri[rows], self.u[rows], self.v[rows])
        n = self._surface.normal(tri, u, v).astype(np.float32)
        return n * np.where(self.cos_in(rows) < 0, np.float32(1), np.float32(-1))[:, None]

    def reflect(self, rows: np.ndarray) -> np.ndarray:
        """Mirror directions of the rays ``rows`` about their shading normals."""
        n = self.shading(rows)
        d = np.take(self.dirs, rows, axis=0)
        return d - 2.0 * np.einsum("ij,ij->i", d, n)[:, None] * n

    @staticmethod
    def _facing(normal, cos_in):
        return normal * np.where(cos_in < 0, np.float32(1), np.float32(-1))[:, None]
