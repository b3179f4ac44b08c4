"""Photon emission: choose emitters in proportion to power, sample origin, direction and weight.

``emit_reference`` (NumPy) and :class:`EmitCL` (``emit.cl``) compute the same numbers from the same
Philox words: photon i draws (w0, u1, u2, u3) from counter (i, EMISSION_STREAM) and u4 from
(i, EMISSION_STREAM + 1) under the key (seed, frame). The emitter is the first whose CDF exceeds
w0. A photon's RGB *weight* is its sample's flux estimate over the selection probability, so
sum(weights) / N estimates the total emitted flux whatever N is (pipeline/photons/emission.py builds the
tables; pbrt-v4 "Light Sources" for the sampling):

  point        direction uniform on the sphere (cos = 1 - 2 u1),     weight I * 4 pi
  spot         uniform in the outer cone's solid angle Omega,        weight I * falloff * Omega
               (cos = 1 - u1 (1 - cos_outer); glTF fall-off ((cos - cos_o) / (cos_i - cos_o))^2 clamped)
  directional  uniform on a disk of radius R facing the light, 1.05 R upstream of the scene centre,
               weight E * pi R^2; or, where the light has a projection map (``light_cells``: n > 0
               cells of side h, pipeline/photons/emission.py), uniform on its cells: cell
               min(floor(u3 n), n - 1), the point (a + u1 h, b + u2 h) in the disk's basis,
               weight E * n h^2
  emissive     uniform on the triangle (sqrt(u1) warp), cosine-weighted about its front normal,
               weight pi * L * A (the emitter's flux)
  sky          one half of a uniform sky (pipeline/scene/sky.py), its travel axis and radiance L as
               a light's direction and radiant: direction uniform on the hemisphere about the axis
               (cos = u1, phi = 2 pi u2), origin uniform on a disk of radius R facing it (u3, u4),
               1.05 R upstream of the scene centre, weight L * 2 pi * pi R^2 (pbrt-v4 "Infinite
               lights": radiance over the pdfs of direction, 1 / 2 pi, and disk point, 1 / pi R^2)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .context import LANES, WORK_GROUP, device_input, device_output, device_table, read_back
from .philox import EMISSION_STREAM, uniforms
from .sampling import around, orthonormal_basis, sincos_poly
from .scatter import surface_offset

POINT, SPOT, DIRECTIONAL, AREA, SKY = 0, 1, 2, 3, 4


@dataclass
class EmissionTables:
    cdf: np.ndarray  # (K,) cumulative selection probability, last = 1
    prob: np.ndarray  # (K,) selection probability
    kind: np.ndarray  # (K,) int32 POINT | SPOT | DIRECTIONAL | AREA | SKY
    index: np.ndarray  # (K,) int64 light index (a sky half's row in the light tables), or global triangle for AREA
    flux: np.ndarray  # (K, 3) emitter flux (used as the weight of AREA photons)
    light_pos: np.ndarray  # (L, 3)
    light_dir: np.ndarray  # (L, 3) unit direction the light points to
    light_rad: np.ndarray  # (L, 3) radiant intensity or irradiance
    cos_outer: np.ndarray  # (L,)
    cos_inner: np.ndarray  # (L,)
    corners: np.ndarray  # (F, 9) float32 world triangle corners
    normals: np.ndarray  # (F, 3) unit front normals
    center: np.ndarray  # (3,) centre of the scene's bounds
    radius: float  # radius of the disk that covers the scene (directional lights)
    epsilon: float  # relative offset of area-light origins off their surface (scatter.py::surface_offset)
    # Projection maps of directional lights (pipeline/photons/emission.py): light l emits from the cells
    # cells[start:start + n], (start, n) = light_cells[l], squares of side cell_size[l] whose corners
    # (a, b) are in the basis of kernels/sampling.orthonormal_basis(light_dir[l]) about the scene
    # centre; n = 0 (or no tables): the whole disk of ``radius``
    light_cells: np.ndarray | None = None  # (L, 2) int64 (start, n)
    cell_size: np.ndarray | None = None  # (L,) float64
    cells: np.ndarray | None = None  # (M, 2) float64 (a, b) of each cell's lower corner

    def projection(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(light_cells, cell_size, cells) as the kernel reads them: no light has a map when not given."""
        n = len(self.light_dir)
        lc = np.zeros((n, 2), np.int64) if self.light_cells is None else np.asarray(self.light_cells, np.int64)
        h = np.zeros(n) if self.cell_size is None else np.asarray(self.cell_size, np.float64)
        cells = np.zeros((0, 2)) if self.cells is None else np.asarray(self.cells, np.float64).reshape(-1, 2)
        if n == 0:  # the kernel reads row 0 of every table whatever the emitter (one row of zeros)
            lc, h = np.zeros((1, 2), np.int64), np.zeros(1)
        return lc.reshape(-1, 2), h.reshape(-1), cells if len(cells) else np.zeros((1, 2))


def emit_reference(t: EmissionTables, photon: np.ndarray,
                   key: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """NumPy twin of ``emit.cl``: origins (n,3) f32, directions (n,3) f32, weights (n,3) f64, emitter."""
    n = len(photon)
    w = uniforms(photon, EMISSION_STREAM, key)
    u4 = uniforms(photon, EMISSION_STREAM + 1, key)[:, 0]
    w0, u1, u2, u3 = w[:, 0], w[:, 1], w[:, 2], w[:, 3]
    e = np.minimum(np.searchsorted(t.cdf, w0, side="right"), len(t.cdf) - 1)
    kind, src = t.kind[e], t.index[e]
    origins, dirs, weights = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))

    a = kind == AREA
    if a.any():
        su = np.sqrt(u1[a])
        b1, b2 = su * (1.0 - u2[a]), su * u2[a]
        b0 = 1.0 - b1 - b2
        c = t.corners[src[a]].astype(np.float64)
        nrm = t.normals[src[a]]
        dirs[a] = around(nrm, np.sqrt(1.0 - u3[a]), 2.0 * np.pi * u4[a], polynomial=True)
        origins[a] = b0[:, None] * c[:, 0:3] + b1[:, None] * c[:, 3:6] + b2[:, None] * c[:, 6:9] \
            + nrm * surface_offset(t.corners[src[a]], t.epsilon)[:, None]
        weights[a] = t.flux[e[a]]
    lights = ~a
    li = src[lights]
    pos, axis, rad = t.light_pos[li], t.light_dir[li], t.light_rad[li]
    origins[lights] = pos
    k = kind[lights]
    sub_u1, sub_u2 = u1[lights], u2[lights]
    d = np.empty((len(li), 3))
    wgt = np.empty((len(li), 3))
    p = k == POINT
    d[p] = around(np.tile([0.0, 0.0, 1.0], (p.sum(), 1)), 1.0 - 2.0 * sub_u1[p], 2.0 * np.pi * sub_u2[p],
                  polynomial=True)
    wgt[p] = rad[p] * (4.0 * np.pi)
    s = k == SPOT
    co, ci = t.cos_outer[li[s]], t.cos_inner[li[s]]
    cos_t = 1.0 - sub_u1[s] * (1.0 - co)
    d[s] = around(axis[s], cos_t, 2.0 * np.pi * sub_u2[s], polynomial=True)
    f = np.minimum(np.maximum((cos_t - co) / (ci - co), 0.0), 1.0)
    wgt[s] = rad[s] * (f * f * (2.0 * np.pi * (1.0 - co)))[:, None]
    dl = k == DIRECTIONAL
    if dl.any():
        r = t.radius * np.sqrt(sub_u1[dl])
        phi = 2.0 * np.pi * sub_u2[dl]
        tt, ss = orthonormal_basis(axis[dl])
        sp, cp = sincos_poly(phi)
        rc, rs = r * cp, r * sp
        scale = np.full(len(r), np.pi * t.radius * t.radius)
        light_cells, cell_size, cells = t.projection()
        start, count = light_cells[li[dl], 0], light_cells[li[dl], 1]
        h = cell_size[li[dl]]
        mapped = count > 0
        if mapped.any():  # a projection map: uniform on its cells
            u3d = u3[lights][dl][mapped]
            j = start[mapped] + np.minimum((u3d * count[mapped].astype(np.float64)).astype(np.int64),
                                           count[mapped] - 1)
            hm = h[mapped]
            rc[mapped] = cells[j, 0] + sub_u1[dl][mapped] * hm
            rs[mapped] = cells[j, 1] + sub_u2[dl][mapped] * hm
            scale[mapped] = count[mapped].astype(np.float64) * hm * hm
        sub = np.flatnonzero(lights)[dl]
        origins[sub] = t.center + (tt * rc[:, None] + ss * rs[:, None]) - axis[dl] * (t.radius * 1.05)
        d[dl] = axis[dl]
        wgt[dl] = rad[dl] * scale[:, None]
    sk = k == SKY
    if sk.any():
        d[sk] = around(axis[sk], sub_u1[sk], 2.0 * np.pi * sub_u2[sk], polynomial=True)
        r = t.radius * np.sqrt(u3[lights][sk])
        tt, ss = orthonormal_basis(d[sk])
        sp, cp = sincos_poly(2.0 * np.pi * u4[lights][sk])
        rc, rs = r * cp, r * sp
        sub = np.flatnonzero(lights)[sk]
        origins[sub] = t.center + (tt * rc[:, None] + ss * rs[:, None]) - d[sk] * (t.radius * 1.05)
        wgt[sk] = rad[sk] * (2.0 * np.pi * (np.pi * t.radius * t.radius))
    dirs[lights] = d
    weights[lights] = wgt
    weights /= t.prob[e][:, None]
    return origins.astype(np.float32), dirs.astype(np.float32), weights, e.astype(np.int32)


class EmitCL:
    """``emit8`` of emit.cl with the emitter tables resident on the device; one per frame state."""

    def __init__(self, tables: EmissionTables):
        import pyopencl as cl

        from .context import device_context, kernel

        self._cl = cl
        self.ctx, self.queue = device_context()
        self.kernel = kernel("emit", "emit8")
        self.tables = tables
        self._pool = None
        self._tables = [device_table(self.ctx, a, dt) for a, dt in (
            (tables.cdf, np.float64), (tables.prob, np.float64), (tables.kind, np.int32),
            (tables.index, np.int64), (tables.flux, np.float64), (tables.light_pos, np.float64),
            (tables.light_dir, np.float64), (tables.light_rad, np.float64),
            (tables.cos_outer, np.float64), (tables.cos_inner, np.float64),
            (tables.corners, np.float32), (tables.normals, np.float64),
            *zip(tables.projection(), (np.int64, np.float64, np.float64)))]

    def __call__(self, photon: np.ndarray, key: tuple[int, int]):
        n = len(photon)
        if n == 0:
            return emit_reference(self.tables, photon, key)
        items = -(-n // LANES)  # eight photons a work item
        padded = -(-items // WORK_GROUP) * WORK_GROUP
        ph = device_input(self.ctx, photon.astype(np.int64, copy=False))
        # Output arrays reused from call to call (no page faults of fresh memory on every call): the
        # result is valid until the next call, and the tracer consumes it before that.
        if self._pool is None or len(self._pool[0]) < n:
            self._pool = [np.empty((n, 3), np.float32), np.empty((n, 3), np.float32),
                          np.empty((n, 3), np.float64), np.empty(n, np.int32)]
        outs = [a[:n] for a in self._pool]
        bufs = [device_output(self.ctx, o) for o in outs]
        t = self.tables
        self.kernel.set_args(np.int64(n), np.uint32(key[0] & 0xFFFFFFFF), np.uint32(key[1] & 0xFFFFFFFF),
                             np.int32(len(t.cdf)), *(np.float64(c) for c in t.center),
                             np.float64(t.radius), np.float64(t.epsilon), ph, *self._tables, *bufs)
        self._cl.enqueue_nd_range_kernel(self.queue, self.kernel, (padded,), (WORK_GROUP,))
        read_back(self.queue, outs, bufs)
        return tuple(outs)
