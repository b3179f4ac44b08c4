"""Abrupt lighting changes seen over regions of elements: Condition (1)'s windows stop at them.

Condition (1) (§5.1, kernels/temporal.py) tests each element's own photon count, whose noise at
tens of hits a frame hides a change of 30-50 %: after a light jumps, many elements keep pooling
the frames before the jump for F_max/2 frames, which the error benchmark sees as the lag and the
flicker around the change (docs/12-error-benchmark.md §3). Summed over a region of many
elements, the same change stands far above the counts' noise. So the counts are summed over cubic
cells of the elements' centroids (instance-local coordinates, so a moving object's cells move
with it), at ``step_levels`` sizes from ``2 x`` the element size, doubling; a frame boundary
(t | t + 1) is a *step* of a cell where its photon rate changes by more than ``step_k`` standard
deviations (Poisson counts):

    z = (R_{t+1}/N_{t+1} - R_t/N_t) / sqrt(R_{t+1}/N_{t+1}^2 + R_t/N_t^2)

and by more than ``step_relative`` of the larger rate, and no window of an element of that cell
crosses the boundary, nor do Condition (1)'s three-frame means (kernels/temporal.py). A slow drift
(a few per cent over the segment) never reaches ``step_k`` between neighbouring frames; a jumping
light, a door, a switched lamp does. The relative bound keeps the test's power from growing with
N_frame: without it, ROOM's guided loop at 640,000 photons cut the windows at the aircraft's moving
light and stalled (docs/06-temporal.md §3). Only the two rows of a boundary are read, so a window's
bits do not depend on the chunk of frames around it (pipeline/collection/maps.py).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from pipeline.config import CollectionConfig

if TYPE_CHECKING:
    from pipeline.scene import ElementMesh


def element_regions(element_vertices: np.ndarray, vertex_local: np.ndarray, element_instance: np.ndarray,
                    cell: float) -> np.ndarray:
    """(E,) int64 region of each element: its instance and the cell of size ``cell`` holding its
    instance-local centroid, numbered densely (0 .. R - 1)."""
    if not cell > 0:
        raise ValueError(f"cell must be positive, got {cell}")
    centroid = vertex_local[np.asarray(element_vertices, np.int64)].mean(axis=1)
    key = np.concatenate([np.asarray(element_instance, np.int64)[:, None],
                          np.floor(centroid / cell).astype(np.int64)], axis=1)
    return np.unique(key, axis=0, return_inverse=True)[1].reshape(-1).astype(np.int64)


def step_boundaries(counts: np.ndarray, n_emitted: np.ndarray, regions: np.ndarray, k: float,
                    relative: float = 0.0) -> np.ndarray:
    """(T - 1, R) bool: region r's photon rate steps by more than ``k`` sigma, and by more than
    ``relative`` of the larger of the two rates, between rows t, t + 1 of ``counts`` (T, E).
    Every row must have photons (``n_emitted`` > 0)."""
    counts = np.asarray(counts)
    n = np.asarray(n_emitted, np.float64)
    if counts.shape[0] != len(n) or np.any(n <= 0):
        raise ValueError("every row of counts needs its photons emitted (> 0)")
    n_regions = int(regions.max()) + 1 if len(regions) else 0
    summed = np.zeros((counts.shape[0], n_regions))
    for t in range(counts.shape[0]):
        summed[t] = np.bincount(regions, weights=counts[t], minlength=n_regions)
    rate = summed / n[:, None]
    var = summed / (n * n)[:, None]
    diff = rate[1:] - rate[:-1]
    both = var[1:] + var[:-1]
    large = np.abs(diff) > relative * np.maximum(rate[1:], rate[:-1])
    return (diff * diff > k * k * both) & large  # zero counts on both sides: 0 > 0, no step


def element_cuts(counts: np.ndarray, n_emitted: np.ndarray, regions: list[np.ndarray],
                 config: CollectionConfig) -> np.ndarray:
    """(T - 1, E) bool: a step (``config.step_k``, ``config.step_relative``) of any of the element's
    regions, one per level of ``regions``, between rows t and t + 1 of ``counts`` (T, E). No
    window crosses it and Condition (1)'s means do not mix its sides (kernels/temporal.py)."""
    cuts = np.zeros((max(counts.shape[0] - 1, 0), counts.shape[1]), bool)
    for level in regions:
        cuts |= step_boundaries(counts, n_emitted, level, config.step_k, config.step_relative)[:, level]
    return cuts


def clamp_windows(back: np.ndarray, fwd: np.ndarray, rows: np.ndarray,
                  cuts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Back and fwd windows (F, E) of the count rows ``rows`` (F,), cut so that none crosses a
    step of its element (``cuts`` (T - 1, E) from :func:`element_cuts`)."""
    n_rows = cuts.shape[0] + 1
    # starts[t, e]: first row of element e's step-free run holding row t; ends[t, e]: its last row
    starts = np.zeros((n_rows, cuts.shape[1]), np.int64)
    ends = np.full((n_rows, cuts.shape[1]), n_rows - 1, np.int64)
    for t in range(1, n_rows):
        starts[t] = np.where(cuts[t - 1], t, starts[t - 1])
    for t in range(n_rows - 2, -1, -1):
        ends[t] = np.where(cuts[t], t, ends[t + 1])
    rows = np.asarray(rows, np.int64)
    b = np.minimum(back.astype(np.int64), rows[:, None] - starts[rows])
    w = np.minimum(fwd.astype(np.int64), ends[rows] - rows[:, None])
    return b.astype(back.dtype), w.astype(fwd.dtype)


def region_levels(elements: ElementMesh, levels: int) -> list[np.ndarray]:
    """The element regions of ``levels`` cell sizes, ``2 x`` the mesh's element size and doubling
    (pipeline/scene/elements.py)."""
    return [element_regions(elements.element_vertices, elements.vertex_local, elements.element_instance,
                            2.0 ** (i + 1) * float(elements.element_size)) for i in range(levels)]
