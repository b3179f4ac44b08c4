"""Ray casting with Embree (embreex) over a posed frame's source triangles, cached per process.

An Embree scene cannot be pickled, so each worker process builds one per distinct frame *state
key* and keeps the most recent few (frames with camera-only motion share one). embreex has no
ray ``tnear`` (it is fixed at 0), so secondary rays start offset along the surface normal
(:func:`offset_origins`); see docs/16-libraries.md §2.

The offset follows the hit's own scale, not the scene's: a float32 point on a triangle whose
corners reach a coordinate of magnitude ``s`` is only known to about ``s x 2^-24`` (pbrt-v4 §6.8,
"Managing Rounding Error": error bounds grow with the magnitude of the corners, OffsetRayOrigin
pushes the origin past them; Mitsuba 3 does the same with ``math::RayEpsilon x (1 + max|p|)``), and
Embree's float32 intersection adds a few roundings of the same size. So each triangle's offset is
``OFFSET_REL x`` its largest corner magnitude: a box beside a kilometre-wide ground plane keeps
its millimetre offsets, and the ground plane gets the larger ones its coordinates need.
"""
from __future__ import annotations

from collections import OrderedDict

import numpy as np
from embreex import mesh_construction, rtcore_scene

from kernels.scatter import surface_offset
from pipeline.scene import FrameState
from pipeline.scene.cutouts import Cutouts, ray_uniforms

MISS = -1
# Holes of alpha-masked surfaces a ray passes before it counts as a miss (a forest seen edge-on)
MAX_HOLES = 64
_CACHE_SIZE = 4
# Relative self-intersection offset: 2^-16 = 256 float32 ulps of the triangle's largest corner
# magnitude, well above the ~10 roundings of Embree's test and the float32 origin (see above).
OFFSET_REL = 2.0 ** -16


class RayCaster:
    """Closest-hit and occlusion queries against one frame state's triangles."""

    def __init__(self, state: FrameState):
        self.state_key = state.state_key
        self._scene = rtcore_scene.EmbreeScene()
        mesh_construction.TriangleMesh(self._scene, np.ascontiguousarray(state.vertices, np.float32),
                                       np.ascontiguousarray(state.faces, np.int32))
        tri = state.vertices.astype(np.float64)[state.faces]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]) * state.front_sign()[:, None]
        self.triangle_area = 0.5 * np.linalg.norm(n, axis=1)
        # unit, towards the front face (counter-clockwise, clockwise where mirrored); zero for a
        # triangle a zero scale collapsed (never hit)
        self.normals = np.divide(n, 2.0 * self.triangle_area[:, None], out=np.zeros_like(n),
                                 where=self.triangle_area[:, None] > 0)
        lo, hi = state.vertices.min(0), state.vertices.max(0)
        self.center = (lo + hi).astype(np.float64) / 2
        self.radius = float(np.linalg.norm(hi - lo)) / 2
        # Self-intersection offsets: ``epsilon`` is relative (the kernels scale it per triangle
        # from its corners, kernels/scatter.cl), ``offsets`` the absolute offset of each triangle
        self.epsilon = OFFSET_REL
        self.offsets = triangle_offsets(tri)
        self.rays_cast = 0
        self.cutouts = Cutouts.of(state)  # alpha-masked and blended surfaces: rays pass their holes
        # Commit the BVH now (embreex commits lazily on the first query).
        self._scene.run(np.zeros((1, 3), np.float32), np.array([[0, 0, 1]], np.float32))

    def intersect(self, origins: np.ndarray,
                  directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Closest hits as embreex returns them: (int32 triangle or -1, float32 u, v, distance);
        Embree's u, v weight the triangle's corners 1 and 2."""
        origins = np.ascontiguousarray(origins, np.float32)
        directions = np.ascontiguousarray(directions, np.float32)
        out = self._scene.run(origins, directions, output=1)
        self.rays_cast += len(origins)
        if self.cutouts is None:
            return out["primID"], out["u"], out["v"], out["tfar"]
        return self._through_holes(origins, directions, out["primID"], out["u"], out["v"], out["tfar"])

    def _through_holes(self, origins: np.ndarray, directions: np.ndarray, tri, u, v, t):
        """Hits with those in a masked, blended or transmissive surface's holes replaced by what lies
        beyond: each such ray starts again just past the hole's plane (the triangle's offset over the
        cosine) along its direction, at most MAX_HOLES times. Random holes are drawn from the ray
        that meets them (``ray_uniforms`` of its start and direction)."""
        tri, u, v, t = (np.array(a) for a in (tri, u, v, t))
        blends = self.cutouts.blends
        rows = np.flatnonzero(self.cutouts.holes(tri, u, v, *self._draws(origins, directions, tri, blends)))
        for _ in range(MAX_HOLES):
            if not len(rows):
                break
            d = directions[rows].astype(np.float64)
            cosine = np.abs(np.einsum("ij,ij->i", self.normals[tri[rows]], d))
            reach = t[rows].astype(np.float64) + self.offsets[tri[rows]] / np.maximum(cosine, 1e-3)
            restart = (origins[rows] + d * reach[:, None]).astype(np.float32)
            out = self._scene.run(restart, directions[rows], output=1)
            self.rays_cast += len(rows)
            tri[rows], u[rows], v[rows] = out["primID"], out["u"], out["v"]
            t[rows] = np.where(out["primID"] >= 0, reach + out["tfar"], out["tfar"])
            draws = self._draws(restart, directions[rows], out["primID"], blends)
            rows = rows[self.cutouts.holes(out["primID"], out["u"], out["v"], *draws)]
        if len(rows):  # a ray past MAX_HOLES holes: a miss rather than a hit on a hole
            tri[rows] = MISS
            t[rows] = np.inf
        return tri, u, v, t

    def _draws(self, origins: np.ndarray, directions: np.ndarray, tri: np.ndarray, blends: bool):
        """(uniforms, |cos| to the hit triangle) of rays for random holes; (None, None) without them."""
        if not blends:
            return None, None
        d = np.asarray(directions, np.float64)
        cosines = np.abs(np.einsum("ij,ij->i", self.normals[np.maximum(tri, 0)], d)) / np.linalg.norm(d, axis=1)
        return ray_uniforms(origins, directions, tri), cosines

    def occluded(self, origins: np.ndarray, directions: np.ndarray, distances: np.ndarray) -> np.ndarray:
        """True where something lies between ``origins`` and ``distances`` along ``directions``."""
        if len(origins) == 0:
            return np.empty(0, bool)
        if self.cutouts is not None:  # only an opaque hit before the distance blocks
            tri, _, _, t = self.intersect(origins, directions)
            return (tri >= 0) & (t < np.asarray(distances, np.float32))
        d = np.ascontiguousarray(distances, np.float32).copy()  # embreex overwrites dists in place
        out = self._scene.run(np.ascontiguousarray(origins, np.float32),
                              np.ascontiguousarray(directions, np.float32), query="OCCLUDED", dists=d)
        self.rays_cast += len(origins)
        return np.asarray(out) != MISS

    def offset_origins(self, points: np.ndarray, triangles: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Move hit points off their surface, to the side ``directions`` leave towards."""
        n = self.normals[triangles]
        side = np.sign(np.einsum("ij,ij->i", n, directions))[:, None]
        side[side == 0] = 1.0
        return points + n * (side * self.offsets[triangles][:, None])


def triangle_offsets(corners: np.ndarray) -> np.ndarray:
    """Absolute self-intersection offset of each triangle of ``corners`` (n, 3, 3): ``OFFSET_REL``
    times its largest corner magnitude, as the photon kernels compute it (kernels/scatter.py)."""
    return surface_offset(np.asarray(corners).reshape(len(corners), 9), OFFSET_REL)


_casters: OrderedDict[str, RayCaster] = OrderedDict()


def caster_for(state: FrameState) -> RayCaster:
    """This process's :class:`RayCaster` for ``state``, built once per distinct state key."""
    caster = _casters.get(state.state_key)
    if caster is None:
        caster = RayCaster(state)
        _casters[state.state_key] = caster
        while len(_casters) > _CACHE_SIZE:
            _casters.popitem(last=False)
    else:
        _casters.move_to_end(state.state_key)
    return caster
