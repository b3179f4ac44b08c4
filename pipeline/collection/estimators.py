"""Illumination maps from one frame's own photons (§4; docs/05-estimators.md §1.2).

Each diffuse photon hit in element t = (v0, v1, v2) with barycentrics (b0, b1, b2) adds b_k x energy
to the accumulator S of vertex v_k; the vertex irradiance is E_v = S_v / (N x A_v) with N the photons
emitted for the frame and A_v the area of v's hat basis function (a third of its elements' areas).
Record energies are photon weights (flux x N, pipeline/store), so S / N is flux and E is W/m^2.
Indirect hits (not the first hit from a light) give the indirect map the compositor reads; direct
hits give a mesh-based direct estimate (§4), kept beside it in the illumination store.

:func:`vertex_irradiance` is the NumPy reference of the temporal gather (kernels/gather.py) for a
one-frame window: keep its signature and arithmetic (float64, np.bincount) as they are.
:func:`reconstruct_task` is the Dask task of Steps 4-5 for a chunk of a segment's frames.
"""
from __future__ import annotations

import hashlib
from collections import OrderedDict
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from kernels.colour import luminance
from pipeline.store import BARY_SCALE

if TYPE_CHECKING:
    from pipeline.scene import ElementMesh, Scene
    from pipeline.store import FrameRecords


def vertex_irradiance(element: npt.ArrayLike, b1: npt.ArrayLike, b2: npt.ArrayLike, energy: npt.ArrayLike,
                      elements_mesh: ElementMesh | npt.ArrayLike, vertex_areas: npt.ArrayLike,
                      n_emitted: int) -> np.ndarray:
    """(V, 3) float64 vertex irradiance E_v = S_v / (N A_v), S_v = sum_j b_k(j) energy_j (docs/05-estimators.md §1.2).

    ``element`` (n,) element ids; ``b1``, ``b2`` (n,) barycentrics of the element's vertices 1 and 2,
    either u16 fixed point (/65535, as stored) or floats; b0 = 1 - b1 - b2. ``energy`` (n, 3) photon
    weights. ``elements_mesh`` an ElementMesh or its (E, 3) ``element_vertices``; ``vertex_areas`` (V,)
    hat-function areas; ``n_emitted`` photons emitted. Vertices of zero area (or N = 0) get 0.
    """
    ev = np.asarray(getattr(elements_mesh, "element_vertices", elements_mesh))
    areas = np.asarray(vertex_areas, dtype=np.float64)
    n_vertices = areas.shape[0]
    element = np.asarray(element, dtype=np.int64)
    w1, w2 = (_bary(b) for b in (b1, b2))
    w0 = 1.0 - w1 - w2
    e = np.asarray(energy, dtype=np.float64).reshape(-1, 3)

    # Splat every hit onto its element's three vertices, accumulating in float64
    verts = ev[element].astype(np.int64)  # (n, 3)
    idx = verts.T.ravel()  # vertex 0 of every hit, then vertex 1, then vertex 2
    weight = np.concatenate([w0, w1, w2])
    s = np.empty((n_vertices, 3), dtype=np.float64)
    for c in range(3):
        s[:, c] = np.bincount(idx, weights=weight * np.tile(e[:, c], 3), minlength=n_vertices)

    denom = float(n_emitted) * areas
    out = np.zeros_like(s)
    ok = denom > 0
    out[ok] = s[ok] / denom[ok, None]
    return out


def records_irradiance(records: FrameRecords, select: np.ndarray, elements_mesh: ElementMesh | npt.ArrayLike,
                       vertex_areas: npt.ArrayLike) -> np.ndarray:
    """:func:`vertex_irradiance` of the records of a FrameRecords where ``select`` (bool (n,)),
    with the same arithmetic and bits (tested): :func:`records_vertex_flux` then
    :func:`flux_to_irradiance`."""
    ev = np.asarray(getattr(elements_mesh, "element_vertices", elements_mesh))
    areas = np.asarray(vertex_areas, dtype=np.float64)
    s = records_vertex_flux(records, select, ev, areas.shape[0])
    return flux_to_irradiance(s, records.photons_emitted, areas)


def records_vertex_flux(records: FrameRecords, select: np.ndarray, element_vertices: npt.ArrayLike,
                        n_vertices: int) -> np.ndarray:
    """(V, 3) float64 S_v = sum_j b_k(j) energy_j over the selected records, as
    :func:`vertex_irradiance` sums them: integer indices instead of boolean masks and the corner
    weights times every channel in one product instead of np.tile (2x faster)."""
    ev = np.asarray(element_vertices)
    pick = np.flatnonzero(select)
    n = pick.shape[0]
    w1, w2 = (_bary(np.take(b, pick)) for b in (records.b1, records.b2))
    weight = np.empty((3, n))
    np.subtract(1.0 - w1, w2, out=weight[0])
    weight[1], weight[2] = w1, w2
    e = np.empty((3, n))  # channel-major float64 energies
    e[...] = np.take(np.asarray(records.energy).reshape(-1, 3), pick, axis=0).T
    idx = np.empty((3, n), np.intp)  # corner-major vertex ids: vertex 0 of every hit, then 1, 2
    idx[...] = np.take(ev, np.take(records.element, pick), axis=0).T
    idx = idx.reshape(-1)
    flux = np.empty((3, 3, n))  # (channel, corner, record): weight x energy
    np.multiply(e[:, None, :], weight[None], out=flux)
    s = np.empty((n_vertices, 3), dtype=np.float64)
    for c in range(3):
        s[:, c] = np.bincount(idx, weights=flux[c].reshape(-1), minlength=n_vertices)
    return s


def flux_to_irradiance(s: np.ndarray, n_emitted: int, vertex_areas: npt.ArrayLike) -> np.ndarray:
    """E_v = S_v / (N A_v) (docs/05-estimators.md §1.2); 0 where A_v = 0 or N = 0."""
    denom = float(n_emitted) * np.asarray(vertex_areas, dtype=np.float64)
    out = np.zeros_like(s)
    ok = denom > 0
    out[ok] = s[ok] / denom[ok, None]
    return out


def _bary(b) -> np.ndarray:
    """Barycentrics as float64: u16 fixed point is divided by BARY_SCALE, floats pass through."""
    b = np.asarray(b)
    if b.dtype.kind in "ui":
        return b.astype(np.float64) / BARY_SCALE
    return b.astype(np.float64)


class FrameGeometry:
    """A posed frame's state and what its reconstruction reads of the element mesh: element areas
    (E,), vertex hat areas (V,) and element centres (E, 3), each computed once however many steps
    use them (the gather's irradiance, the direct estimate, the adaptation luminance)."""

    def __init__(self, scene: Scene, elements: ElementMesh, frame: int):
        self.scene, self.elements, self.frame = scene, elements, int(frame)
        self.state = scene.pose_frame(self.frame)
        self.areas = elements.areas(self.state)
        # what ElementMesh.vertex_areas computes, from the areas above
        self.vertex_areas = np.bincount(elements.element_vertices.ravel(), weights=np.repeat(self.areas / 3.0, 3),
                                        minlength=elements.n_vertices)
        self._centres = None

    @property
    def centres(self) -> np.ndarray:
        if self._centres is None:
            self._centres = self.elements.element_positions(self.state).mean(axis=1)
        return self._centres


_GEOMETRY: OrderedDict = OrderedDict()  # (id(scene), id(elements), frame) -> FrameGeometry
GEOMETRY_FRAMES = 48  # a reconstruction chunk's frames and then some


def frame_geometry(scene: Scene, elements: ElementMesh, frame: int) -> FrameGeometry:
    """:class:`FrameGeometry` of a frame number, kept per process for the last GEOMETRY_FRAMES
    frames (an entry holds its scene and mesh, so their ids cannot be reused while it lives)."""
    key = (id(scene), id(elements), int(frame))
    found = _GEOMETRY.get(key)
    if found is not None and found.scene is scene and found.elements is elements:
        _GEOMETRY.move_to_end(key)
        return found
    found = _GEOMETRY[key] = FrameGeometry(scene, elements, frame)
    while len(_GEOMETRY) > GEOMETRY_FRAMES:
        _GEOMETRY.popitem(last=False)
    return found


def vertex_moments(element: npt.ArrayLike, b1: npt.ArrayLike, b2: npt.ArrayLike, energy: npt.ArrayLike,
                   element_vertices: npt.ArrayLike, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """(V,) luminance flux S_v = sum_j b_k(j) Y_j and its squared-weight sum Q_v = sum_j b_k(j)^2 Y_j^2
    (docs/05-estimators.md §1.3): the moments the pilot's energy-based error reads
    (pipeline/segments/decisions.energy_error)."""
    ev = np.asarray(element_vertices)
    w1, w2 = _bary(b1), _bary(b2)
    w = np.concatenate([1.0 - w1 - w2, w1, w2])
    y = np.tile(luminance(np.asarray(energy, np.float64).reshape(-1, 3)), 3)
    idx = ev[np.asarray(element, np.int64)].astype(np.int64).T.ravel()
    return (np.bincount(idx, weights=w * y, minlength=n_vertices),
            np.bincount(idx, weights=(w * y) ** 2, minlength=n_vertices))


def map_digest(*maps: np.ndarray) -> str:
    """16 hex digits of SHA-256 over the float32 bytes of maps: what a frame's pixels read of them."""
    h = hashlib.sha256()
    for m in maps:
        h.update(np.ascontiguousarray(m, dtype=np.float32).tobytes())
    return h.hexdigest()[:16]
