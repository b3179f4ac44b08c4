"""Hits on the element mesh: element ids and the indirect irradiance blended inside them.

``lookup_reference`` (NumPy: ElementMesh.locate's arithmetic, then E0 + b1 (E1 - E0) + b2 (E2 - E0)
in float32) and :class:`LookupCL` (``lookup8`` in surface.cl) give the same elements and the same
irradiance; the compositor (pipeline/frames/shading_tables.py) uses them for every camera and reflection hit.
"""
from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .cells import locate_in_triangles
from .context import LANES, WORK_GROUP, device_input, device_output, read_back


def lookup_reference(tri_n: npt.ArrayLike, tri_offset: npt.ArrayLike, element_irradiance: np.ndarray | None,
                     tri: npt.ArrayLike, u: npt.ArrayLike, v: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray | None]:
    """(element (n,) int64, irradiance (n, 3) float32 or None) for hits (tri, u, v)."""
    element, b1, b2 = locate_in_triangles(tri_n, tri_offset, tri, u, v)
    if element_irradiance is None:
        return element, None
    c = np.take(element_irradiance, element, axis=0)
    blend = c[:, 0] + b1.astype(np.float32)[:, None] * c[:, 1] + b2.astype(np.float32)[:, None] * c[:, 2]
    return element, blend


class LookupCL:
    """``lookup8`` with the element tables on the device; one per frame's illumination map."""

    def __init__(self, tri_n: np.ndarray, tri_offset: np.ndarray, element_irradiance: np.ndarray | None):
        import pyopencl as cl  # only when a kernel runs: twins need no OpenCL

        from .context import device_context, kernel  # imports pyopencl: only when a kernel runs

        self._cl = cl
        self.ctx, self.queue = device_context()
        self.kernel = kernel("surface", "lookup8")
        self.blend = element_irradiance is not None
        ro = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
        table = (np.ascontiguousarray(element_irradiance, np.float32).reshape(-1) if self.blend
                 else np.zeros(9, np.float32))
        self._tables = [cl.Buffer(self.ctx, ro, hostbuf=np.ascontiguousarray(a)) for a in (
            np.asarray(tri_n, np.int32), np.asarray(tri_offset, np.int64), table)]

    def __call__(self, tri, u, v):
        m = len(tri)
        if m == 0:
            return np.empty(0, np.int64), (np.empty((0, 3), np.float32) if self.blend else None)
        items = -(-m // LANES)
        padded = -(-items // WORK_GROUP) * WORK_GROUP
        inputs = [device_input(self.ctx, np.asarray(a, dt)) for a, dt in
                  ((tri, np.int32), (u, np.float32), (v, np.float32))]
        cell = np.empty(m, np.int64)
        blend = np.empty((m if self.blend else 1, 3), np.float32)
        outputs = [device_output(self.ctx, cell), device_output(self.ctx, blend)]
        self.kernel.set_args(np.int64(m), np.int32(self.blend), *inputs, *self._tables, *outputs)
        self._cl.enqueue_nd_range_kernel(self.queue, self.kernel, (padded,), (WORK_GROUP,))
        read_back(self.queue, [cell, blend], outputs)
        return cell, (blend if self.blend else None)
