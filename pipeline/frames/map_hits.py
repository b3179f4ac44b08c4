"""Where a frame's camera paths read the illumination map, kept so that other maps can light the
same paths without tracing them again.

A camera sample reads the map at most once: at the diffuse hit that ends its path
(pipeline/frames/camera_paths.py), where its indirect layer gets (rho / pi * E(hit)) * throughput.
Nothing else on the path depends on the map, so recording that hit (triangle, Embree's u, v, the
factor rho / pi and the throughput of the reflections before it) is enough to give the indirect
layer of any map: :meth:`MapHits.indirect` does the same float32 operations in the same order as
the path loop, so its bits are those of ``render_frame`` with that map
(tests/frames/test_map_hits.py). Step 3 judges the even and odd halves at K several times with
the same paths (pipeline/segments/halves.py); this is what lets it trace them once.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from kernels.surface import LookupCL

from .pixel_samples import sample_means
from .shading_tables import element_table

if TYPE_CHECKING:
    from pipeline.scene import ElementMesh


HIT_BYTES = 44  # bytes a kept hit takes: sample, tri, u, v, scale and throughput


def hits_bytes(n_samples: int) -> int:
    """The most a frame's :class:`MapHits` can take: one hit a camera sample."""
    return HIT_BYTES * n_samples


class MapHitRecorder:
    """Collects the map-reading hits of the path loop, chunk by chunk (``trace_samples(record=...)``)."""

    def __init__(self) -> None:
        self._parts: list[tuple] = []

    def add(self, samples: np.ndarray, tri: np.ndarray, u: np.ndarray, v: np.ndarray, scale: np.ndarray,
            throughput: np.ndarray | None, rows: np.ndarray) -> None:
        """The hits ``rows`` of one depth: their camera samples (global counters), Embree's
        (tri, u, v), the factor rho / pi and the throughput before them (None: camera rays, one)."""
        t = (np.ones((len(rows), 3), np.float32) if throughput is None else np.take(throughput, rows, axis=0))
        self._parts.append((np.take(samples, rows), np.take(tri, rows), np.take(u, rows), np.take(v, rows),
                            np.take(scale, rows, axis=0), t))

    def finish(self, width: int, height: int, spp: int) -> MapHits:
        """The hits of a ``width`` x ``height`` frame of ``spp`` samples a pixel."""
        if not self._parts:
            empty = np.empty((0, 3), np.float32)
            return MapHits(width, height, spp, np.empty(0, np.int64), np.empty(0, np.int32), np.empty(0, np.float32),
                           np.empty(0, np.float32), empty, empty)
        sample, tri, u, v, scale, thr = (np.concatenate(c) for c in zip(*self._parts))
        return MapHits(width, height, spp, sample.astype(np.int64, copy=False), tri.astype(np.int32, copy=False),
                       u.astype(np.float32, copy=False), v.astype(np.float32, copy=False),
                       scale.astype(np.float32, copy=False), thr.astype(np.float32, copy=False))


@dataclass(frozen=True)
class MapHits:
    """The map-reading hit of every camera sample that has one (n hits) in a ``width`` x ``height``
    frame of ``spp`` samples a pixel: ``sample`` (n,) the sample's counter (pixel * spp + sample),
    ``tri``, ``u``, ``v`` Embree's hit, ``scale`` (n, 3) rho / pi there, ``throughput`` (n, 3) the
    reflections' weight before it (ones for a camera ray's own hit)."""

    width: int
    height: int
    spp: int
    sample: np.ndarray
    tri: np.ndarray
    u: np.ndarray
    v: np.ndarray
    scale: np.ndarray
    throughput: np.ndarray

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in (self.sample, self.tri, self.u, self.v, self.scale, self.throughput))

    def indirect(self, elements: ElementMesh, irradiance: np.ndarray) -> np.ndarray:
        """The indirect layer (H, W, 3) float32 that ``irradiance`` (V, 3) gives along these paths:
        the bits of ``render_frame(..., irradiance, paths).indirect``."""
        lookup = LookupCL(elements.triangle_n, elements.triangle_offset[:-1], element_table(elements, irradiance))
        _, e = lookup(self.tri, self.u, self.v)
        n_pixels = self.width * self.height
        per_sample = np.zeros((n_pixels * self.spp, 3), np.float32)
        per_sample[self.sample] += (self.scale * e) * self.throughput  # one hit a sample at most
        if self.spp == 1:
            return per_sample.reshape(self.height, self.width, 3)
        out = np.empty((1, n_pixels, 3), np.float32)
        sample_means(per_sample.reshape(1, n_pixels, self.spp, 3), out)
        return out[0].reshape(self.height, self.width, 3)
