"""The element mesh: the paper's dense triangle mesh on which photons are bucketed (§4, §5.3).

Every source triangle is split uniformly into ``n x n`` congruent sub-triangles (elements),
``n = ceil(longest edge / element_size)`` measured in world space at the first frame, so every
element edge is at most ``element_size`` (``n`` at most ``MAX_SPLIT``: a huge triangle gets
coarser elements, with a warning). A uniform split keeps element shapes as good as the
source triangle's and makes locating a hit analytic: the photon tracer intersects the *source*
triangles with Embree and maps the hit's barycentric coordinates to (element, barycentrics)
with :meth:`ElementMesh.locate`, with no per-element geometry in the ray-tracing scene.

Lattice of one source triangle (P0, P1, P2), barycentrics (u, v) of P1 and P2 as Embree reports
them: lattice point (a, b), a + b <= n, sits at P0 + a/n (P1 - P0) + b/n (P2 - P0).
"Up" cell (a, b), a + b <= n - 1, has vertices [(a,b), (a+1,b), (a,b+1)];
"down" cell (a, b), a + b <= n - 2, has vertices [(a+1,b), (a+1,b+1), (a,b+1)].
Within a triangle the up cells come first (row-major in a, then b), then the down cells.

Element ids are stable for all frames: instance order, then source triangle order, then cell order.
Vertices are shared between elements of one instance when they coincide and their source triangles
face within 45 degrees of each other (so a box corner keeps separate floor and wall vertices and
vertex lighting does not bleed round corners). Positions are kept in instance-local coordinates
and posed on demand; nothing is stored per frame.

A deforming instance (a skin or morph targets, pipeline/scene/animation.py) keeps the same elements,
built on its rest (bind) shape: each of its vertices remembers one source triangle and its lattice
weights there, and is posed as that point of the posed source triangle, so the elements stay on the
surface the rays hit and only their positions move.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from kernels.cells import locate_in_triangles

from ..errors import SceneError
from .cutouts import Cutouts, element_coverage
from .scene import FrameState, Scene

log = logging.getLogger(__name__)
# Vertices of one instance closer than this fraction of its bounding-box diagonal are merged.
_MERGE_TOLERANCE = 1e-6
# Coincident lattice points are one shared vertex only when their triangles' normals agree this well.
_SHARE_COS = np.cos(np.radians(45.0))
# A guard against an element size that would exhaust memory.
MAX_ELEMENTS = 20_000_000
# The largest split of one source triangle (128 x 128 = 16,384 elements): a ground plane
# kilometres wide gets coarser elements instead of refusing the scene's element size. 512 x 512
# let a two-triangle ground make half a million elements, which took a tiny render to 2 GB.
MAX_SPLIT = 128
# Posed coordinates beyond this are refused: squared lengths (dot products in float32, in the
# kernels and the compositor) would overflow float32's 3.4e38.
MAX_COORDINATE = 1e18


def lattice_index(a: int, b: int, n: int) -> int:
    """Index of lattice point (a, b) among the (n+1)(n+2)/2 points of a triangle."""
    return a * (n + 1) - a * (a - 1) // 2 + b


def _cells(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Lattice (a, b) coordinates of every point, and the (n*n, 3) lattice indices of every cell."""
    pts = np.array([(a, b) for a in range(n + 1) for b in range(n + 1 - a)], dtype=np.int64)
    up = [(lattice_index(a, b, n), lattice_index(a + 1, b, n), lattice_index(a, b + 1, n))
          for a in range(n) for b in range(n - a)]
    down = [(lattice_index(a + 1, b, n), lattice_index(a + 1, b + 1, n), lattice_index(a, b + 1, n))
            for a in range(n - 1) for b in range(n - 1 - a)]
    return pts, np.array(up + down, dtype=np.int64).reshape(-1, 3)


@dataclass
class ElementMesh:
    """Elements of a scene at one element size; see the module docstring for the layout."""

    element_size: float
    triangle_n: np.ndarray  # (F,) int32 split factor of each global source triangle
    triangle_offset: np.ndarray  # (F+1,) int64 first element of each source triangle
    element_vertices: np.ndarray  # (E, 3) int32 shared-vertex ids
    element_instance: np.ndarray  # (E,) int32
    element_triangle: np.ndarray  # (E,) int32 global source triangle
    vertex_local: np.ndarray  # (V, 3) float64 instance-local positions
    vertex_instance: np.ndarray  # (V,) int32
    local_areas: np.ndarray  # (E,) float64 areas in instance-local coordinates
    instance_elements: np.ndarray  # (I+1,) int64 element range of each instance
    triangle_source_face: np.ndarray  # (F,) int64 index of each source triangle in its glTF primitive
    vertex_triangle: np.ndarray | None = None  # (V,) int64 a global source triangle holding the vertex
    vertex_lattice: np.ndarray | None = None  # (V, 2) float64 its weights of corners 1 and 2 there
    # (E,) solid fraction of each element of an alpha-masked surface (pipeline/scene/cutouts.py), None without
    coverage: np.ndarray | None = None

    @property
    def n_elements(self) -> int:
        return len(self.element_vertices)

    @property
    def n_vertices(self) -> int:
        return len(self.vertex_local)

    @property
    def element_source(self) -> np.ndarray:
        """(E, 2) element -> (instance, triangle index in the instance's glTF primitive)."""
        return np.stack([self.element_instance, self.triangle_source_face[self.element_triangle]], axis=1)

    # --- construction -------------------------------------------------------------------------------

    @classmethod
    def build(cls, scene: Scene, element_size: float | None = None) -> "ElementMesh":
        """Subdivide the scene's triangles, posed at the first frame, to ``element_size``."""
        size = float(element_size if element_size is not None else scene.element_size)
        if not size > 0:
            raise SceneError(f"element_size {size} must be positive", path=str(scene.path), field="element_size")
        state = scene.pose_frame(scene.timeline.first, every_node=True)  # hidden meshes get elements too
        world = state.vertices.astype(np.float64)[state.faces]
        if not np.isfinite(world).all():  # node transforms that overflow float32 (or a NaN on the way)
            raise SceneError("the posed triangles of the first frame have NaN or Inf coordinates (a node's "
                             "transform overflows float32)", path=str(scene.path), field="nodes")
        if np.abs(world).max(initial=0.0) > MAX_COORDINATE:
            raise SceneError(f"the posed triangles of the first frame have coordinates up to "
                             f"{np.abs(world).max():.3g}, beyond {MAX_COORDINATE:g} (squared lengths overflow "
                             "float32)", path=str(scene.path), field="nodes")
        edges = np.stack([np.linalg.norm(world[:, (k + 1) % 3] - world[:, k], axis=1) for k in range(3)], 1)
        wanted = np.maximum(1, np.ceil(edges.max(1) / size - 1e-9))
        capped = wanted > MAX_SPLIT
        # A few huge triangles (a ground plane) get coarser elements; an element size too small for
        # most of the scene is refused as asked, not silently coarsened everywhere
        asked = float((wanted ** 2).sum())
        tri_n = np.minimum(wanted, MAX_SPLIT).astype(np.int64)
        total = int((tri_n ** 2).sum())
        if not total <= MAX_ELEMENTS or (asked > MAX_ELEMENTS and capped.mean() > 0.5):
            raise SceneError(f"element_size {size:g} gives {asked:.0f} elements, more than {MAX_ELEMENTS} (the posed "
                             f"scene's triangles are up to {float(edges.max()):.3g} long; --element-size or "
                             "scenes.extras.photonloom.element_size sets a coarser one)",
                             path=str(scene.path), field="element_size")
        if capped.any():
            log.warning("%s: %d triangle(s) longer than %d x element_size %g are split %d x %d (elements up to "
                        "%.3g wide)", scene.path, int(capped.sum()), MAX_SPLIT, size, MAX_SPLIT,
                        MAX_SPLIT, float(edges.max() / MAX_SPLIT))
        offsets = np.concatenate([[0], np.cumsum(tri_n ** 2)])

        # Local-space corners of every global source triangle
        local_corners = np.concatenate([inst.vertices[inst.faces] for inst in scene.instances])
        tri_inst = state.triangle_instance.astype(np.int64)

        occ_pos = []  # per lattice-point occurrence: local position
        occ_tri = []  # its source triangle
        occ_lattice = []  # its weights of the triangle's corners 1 and 2
        elem_occ = np.empty((total, 3), dtype=np.int64)  # element corners as occurrence indices
        occ_count = 0
        for n in np.unique(tri_n):
            tris = np.flatnonzero(tri_n == n)
            pts, cells = _cells(int(n))
            c = local_corners[tris]  # (m, 3, 3)
            wa = pts[:, 0] / n
            wb = pts[:, 1] / n
            pos = (c[:, None, 0] + wa[None, :, None] * (c[:, None, 1] - c[:, None, 0])
                   + wb[None, :, None] * (c[:, None, 2] - c[:, None, 0]))  # (m, L, 3)
            n_pts = len(pts)
            occ_pos.append(pos.reshape(-1, 3))
            occ_tri.append(np.repeat(tris, n_pts))
            occ_lattice.append(np.tile(np.stack([wa, wb], axis=1), (len(tris), 1)))
            base = occ_count + np.arange(len(tris)) * n_pts  # (m,)
            rows = offsets[tris][:, None] + np.arange(n * n)[None, :]  # (m, n*n)
            elem_occ[rows.ravel()] = (base[:, None, None] + cells[None, :, :]).reshape(-1, 3)
            occ_count += len(tris) * n_pts
        occ_pos = np.concatenate(occ_pos)
        occ_tri = np.concatenate(occ_tri)
        occ_lattice = np.concatenate(occ_lattice)

        occ_vertex = _share_vertices(occ_pos, tri_inst[occ_tri], _local_normals(local_corners)[occ_tri],
                                     scene)
        n_vertices = int(occ_vertex.max()) + 1
        vertex_local = np.empty((n_vertices, 3))
        vertex_local[occ_vertex] = occ_pos
        vertex_instance = np.empty(n_vertices, dtype=np.int32)
        vertex_instance[occ_vertex] = tri_inst[occ_tri]
        vertex_triangle = np.empty(n_vertices, dtype=np.int64)
        vertex_triangle[occ_vertex] = occ_tri
        vertex_lattice = np.empty((n_vertices, 2))
        vertex_lattice[occ_vertex] = occ_lattice
        element_vertices = occ_vertex[elem_occ].astype(np.int32)
        element_triangle = np.repeat(np.arange(len(tri_n)), tri_n ** 2).astype(np.int32)
        element_instance = tri_inst[element_triangle].astype(np.int32)
        p = occ_pos[elem_occ]
        local_areas = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
        inst_elems = np.searchsorted(element_instance, np.arange(len(scene.instances) + 1))
        coverage = element_coverage(Cutouts(scene.materials, state.triangle_material, scene.corner_attributes),
                                    tri_n, offsets, _cells)
        return cls(size, tri_n.astype(np.int32), offsets, element_vertices, element_instance,
                   element_triangle, vertex_local, vertex_instance, local_areas, inst_elems,
                   np.concatenate([inst.source_faces for inst in scene.instances]), vertex_triangle,
                   vertex_lattice, coverage)

    # --- queries ----------------------------------------------------------------------------------

    def locate(self, triangle: np.ndarray, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Map hits on source triangles (Embree's barycentrics u, v) to (element, b1, b2).

        ``b1``, ``b2`` are the barycentric weights of the element's vertices 1 and 2
        (vertex 0 gets ``1 - b1 - b2``); all three are clipped to [0, 1].
        """
        return locate_in_triangles(self.triangle_n, self.triangle_offset, triangle, u, v)

    def vertex_positions(self, state: FrameState) -> np.ndarray:
        """(V, 3) world positions of the shared vertices in a posed frame: the instance's matrix
        applied to the local position, or, for a deforming instance, the vertex's lattice point on
        its posed source triangle (module docstring)."""
        m = state.instance_matrices[self.vertex_instance]
        out = np.einsum("vij,vj->vi", m[:, :3, :3], self.vertex_local) + m[:, :3, 3]
        deformed = getattr(state, "deformed_instances", ())
        if deformed:
            rows = np.flatnonzero(np.isin(self.vertex_instance, deformed))
            c = state.vertices.astype(np.float64)[state.faces[self.vertex_triangle[rows]]]  # (n, 3, 3)
            wa, wb = self.vertex_lattice[rows, :1], self.vertex_lattice[rows, 1:]
            out[rows] = c[:, 0] + wa * (c[:, 1] - c[:, 0]) + wb * (c[:, 2] - c[:, 0])
        return out

    def element_positions(self, state: FrameState) -> np.ndarray:
        """(E, 3, 3) world corners of every element in a posed frame."""
        return self.vertex_positions(state)[self.element_vertices]

    def areas(self, state: FrameState) -> np.ndarray:
        """(E,) world areas in a posed frame: local areas times s^2 where the instance's
        transform is a similarity (rotation, translation, uniform scale s), recomputed otherwise
        (non-uniform or animated non-uniform scale, or a deforming instance)."""
        out = np.empty(self.n_elements)
        deformed = set(getattr(state, "deformed_instances", ()))
        posed = self.vertex_positions(state) if deformed else None
        for i, m in enumerate(state.instance_matrices):
            lo, hi = self.instance_elements[i], self.instance_elements[i + 1]
            if i in deformed:  # a skin or morph: the areas of the posed elements
                p = posed[self.element_vertices[lo:hi]]
                out[lo:hi] = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
                continue
            lin = m[:3, :3]
            gram = lin.T @ lin
            s2 = np.trace(gram) / 3.0
            if np.allclose(gram, s2 * np.eye(3), rtol=1e-9, atol=1e-12 * max(s2, 1e-30)):
                out[lo:hi] = self.local_areas[lo:hi] * s2
            else:
                p = (self.vertex_local[self.element_vertices[lo:hi]] @ lin.T)
                out[lo:hi] = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
        return out if self.coverage is None else out * self.coverage  # a masked surface's holes gather nothing

    def vertex_areas(self, state: FrameState) -> np.ndarray:
        """(V,) area of each vertex's hat basis function, sum of a third of its elements' areas
        (docs/05-estimators.md §1.2): the denominator of vertex irradiance."""
        return np.bincount(self.element_vertices.ravel(), weights=np.repeat(self.areas(state) / 3.0, 3),
                           minlength=self.n_vertices)


def _local_normals(corners: np.ndarray) -> np.ndarray:
    n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _share_vertices(pos: np.ndarray, inst: np.ndarray, normal: np.ndarray, scene: Scene) -> np.ndarray:
    """Shared-vertex id of every lattice-point occurrence (see module docstring), numbered in
    order of first occurrence so ids are deterministic and grouped by instance."""
    tol = np.array([
        max(_MERGE_TOLERANCE * float(np.linalg.norm(i.vertices.max(0) - i.vertices.min(0))), 1e-12)
        for i in scene.instances
    ])
    q = np.round(pos / tol[inst][:, None]).astype(np.int64)
    keys = np.concatenate([inst[:, None], q], axis=1)
    _, group = np.unique(keys, axis=0, return_inverse=True)
    group = group.ravel()
    cluster = np.full(len(pos), -1, dtype=np.int64)
    next_id = 0
    while True:
        todo = np.flatnonzero(cluster < 0)
        if len(todo) == 0:
            break
        g = group[todo]
        # the first unassigned occurrence of each group is that group's representative
        first_in_group = np.full(group.max() + 1, -1, dtype=np.int64)
        first_in_group[g[::-1]] = todo[::-1]
        rep = first_in_group[g]
        join = np.einsum("ij,ij->i", normal[todo], normal[rep]) > _SHARE_COS
        join |= rep == todo
        members = todo[join]
        cluster[members] = next_id + rep[join]  # unique per representative for this round
        next_id += len(pos)
    # renumber in order of first occurrence
    _, first, inverse = np.unique(cluster, return_index=True, return_inverse=True)
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    return rank[inverse.ravel()]
