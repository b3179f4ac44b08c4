"""Illumination reconstruction from photon records over temporal windows (§4, §5.2.4, §5.2.3).

Three steps, each an OpenCL kernel in ``gather.cl`` with a NumPy float64 twin here:

1. ``element_sums``: per (frame g, element e, parity p, corner k) the sums over e's records of g
   ``T_rgb = sum b_k * energy`` and ``T_Q = sum b_k^2 * Y^2`` (Y = Rec. 709 luminance of the
   energy; Q feeds the variance estimate of the adaptive filter, docs/05-estimators.md §1.3). Each record is
   read once in total, however many windows use its frame.
2. window sums: for output frame f and element e with window W = [f - back, f + fwd]
   (kernels/temporal.py) the pooled flux per corner ``U = sum_{g in W} T_g / sum_{g in W} N_g``
   (``U_Q = sum T_Q / (sum N_g)^2``). Every photon of the window counts once against all photons
   emitted in the window's frames: photons are normalised by the frames collected, and frames with
   different N_frame (§5.2.3) are pooled at their photon weight. With the parity split each half
   is normalised by half the photons, so I1 and I2 (§5.2.3) both estimate the full irradiance.
3. vertex flux: element corners -> vertices in a fixed order (a CSR vertex -> element-corner
   map), ``S_v = sum U``; irradiance ``E_v = S_v / A_v`` (docs/05-estimators.md §1.2; for a one-frame window
   exactly the E_v = S_v / (N A_v) of pipeline/collection/estimators.py).

The device path is the one pipeline/collection/maps.py runs: :func:`element_sums_cl` once per frame (kept
per worker), then :func:`frame_sums_flux_cl` fills an element-major prefix table over the frames on
the device (row j+1 = row j + frame j's sums; an element's rows are contiguous, one launch a
frame) and does steps 2 and 3 in one launch: a window sum is the difference of two rows whatever
the window's length. Prefix sums were chosen by measurement (on the ATRIUM-size case, 43,000
elements, F_max = 44, mean window 42 frames, the vertex step took 1.1 ms/frame against 5.7 ms/frame
adding the window's rows). Cancellation is harmless in float64: a difference of prefix sums over at
most a few hundred frames loses ~1e-13 relative to the range's total. NumPy twins:
:func:`element_sums_reference` and :func:`window_flux_reference`.

No atomics anywhere: every output is written by one work item adding in a fixed order, so
results are bitwise repeatable (docs/15-opencl.md §2).
"""
from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
import pyopencl as cl

from .colour import LUMA
from .context import device_context, kernel, scratch
from .record_layout import BARY_SCALE, DIRECT_BIT, PARITY_BIT

if TYPE_CHECKING:
    from typing import Protocol

    class _SortedRecords(Protocol):
        """What the gather reads of one frame's records (the store's FrameRecords has it): sorted by
        element, element e's records ``[offsets[e], offsets[e + 1])``."""

        @property
        def key(self) -> np.ndarray: ...
        @property
        def b1(self) -> np.ndarray: ...
        @property
        def b2(self) -> np.ndarray: ...
        @property
        def energy(self) -> np.ndarray: ...
        @property
        def offsets(self) -> np.ndarray: ...

KINDS = {"indirect": 1, "direct": 2, "all": 3}
SLOTS = 12  # 3 corners x (R, G, B, Q)


def _concat_frames(frames):
    """Concatenate per-frame element-sorted records into one segment list (frame-major)."""
    frames = list(frames)
    if not frames:
        raise ValueError("no frames of records to gather")
    n_elements = len(frames[0].offsets) - 1

    def joined(arrays):  # one frame's arrays as they are: a batch summary gathers one (no copy)
        arrays = list(arrays)
        return np.ascontiguousarray(arrays[0]) if len(arrays) == 1 else np.concatenate(arrays)
    key = joined(np.asarray(r.key, np.uint32) for r in frames)
    b1 = joined(np.asarray(r.b1, np.uint16) for r in frames)
    b2 = joined(np.asarray(r.b2, np.uint16) for r in frames)
    energy = joined(np.asarray(r.energy, np.float32).reshape(-1, 3) for r in frames)
    parts, base = [np.zeros(1, np.int64)], 0
    for r in frames:
        off = np.asarray(r.offsets, np.int64)
        if len(off) != n_elements + 1 or off[0] != 0 or off[-1] != len(r.key):
            raise ValueError("records' offsets do not match their element count")
        parts.append(off[1:] + base)
        base += int(off[-1])
    if base >= 2**32:
        raise ValueError(f"{base:,} records in one call; gather at most 2^32 - 1 at a time")
    return key, b1, b2, energy, np.concatenate(parts).astype(np.uint32), len(frames), n_elements


def _upload(ctx, a: np.ndarray) -> cl.Buffer:
    mf = cl.mem_flags
    return cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a if a.size else np.zeros(1, a.dtype))


def _in_place(ctx, a: np.ndarray) -> cl.Buffer:
    """A read-only buffer over the host array itself: PoCL's CPU device reads host memory in place,
    so the records are not copied again after their concatenation. The caller keeps the buffer
    (which keeps ``a``) until the kernel that reads it has finished."""
    mf = cl.mem_flags
    a = np.ascontiguousarray(a) if a.size else np.zeros(1, a.dtype)
    return cl.Buffer(ctx, mf.READ_ONLY | mf.USE_HOST_PTR, hostbuf=a)


def element_sums_cl(frames: Iterable[_SortedRecords], *, kind: str = "indirect",
                    split_parity: bool = False) -> np.ndarray:
    """Step 1 on PoCL for a list of frames' records (objects with ``key``, ``b1``, ``b2``,
    ``energy``, ``offsets`` sorted by element, like the store's FrameRecords).

    Returns (J, E, P, 3, 4) float64: per frame, element, parity (P = 2 with ``split_parity``,
    even then odd photons; else 1), corner k and (R, G, B, Q).
    """
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")
    n_parity = 2 if split_parity else 1
    key, b1, b2, energy, offsets, n_frames, n_elements = _concat_frames(frames)  # validates
    out = np.zeros((n_frames, n_elements, n_parity, 3, 4))
    if out.size == 0:
        return out
    ctx, queue = device_context()
    d_out = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, size=out.nbytes)
    records = [_in_place(ctx, a) for a in (key, b1, b2, energy, offsets)]
    n_segments = n_frames * n_elements
    kernel("gather", "element_sums")(queue, (n_segments * n_parity,), None, *records, np.int64(n_segments),
                                     np.uint32(KINDS[kind]), np.int32(n_parity), d_out)
    cl.enqueue_copy(queue, out, d_out)  # blocking: the buffers read the host arrays in place until here
    return out


def element_sums_reference(frames: Iterable[_SortedRecords], *, kind: str = "indirect",
                           split_parity: bool = False) -> np.ndarray:
    """NumPy twin of :func:`element_sums_cl`."""
    key, b1, b2, energy, offsets, n_frames, n_elements = _concat_frames(frames)
    n_parity = 2 if split_parity else 1
    segment = np.repeat(np.arange(n_frames * n_elements), np.diff(offsets))
    direct = (key & DIRECT_BIT) != 0
    keep = (direct & bool(KINDS[kind] & 2)) | (~direct & bool(KINDS[kind] & 1))
    parity = ((key & PARITY_BIT) != 0).astype(np.int64) if split_parity else np.zeros(len(key), np.int64)
    w1 = b1.astype(np.float64) / BARY_SCALE
    w2 = b2.astype(np.float64) / BARY_SCALE
    w = np.stack([1.0 - w1 - w2, w1, w2], axis=1)  # (n, 3)
    e64 = energy.astype(np.float64)
    y = e64 @ np.asarray(LUMA)
    values = np.concatenate([w[:, :, None] * e64[:, None, :], (w * w * (y * y)[:, None])[:, :, None]],
                            axis=2)  # (n, 3 corners, 4)
    bins = (segment * n_parity + parity)[keep]
    flat = np.zeros((n_frames * n_elements * n_parity, 12))
    for j in range(12):
        flat[:, j] = np.bincount(bins, weights=values.reshape(-1, 12)[keep, j],
                                 minlength=flat.shape[0])
    return flat.reshape(n_frames, n_elements, n_parity, 3, 4)


def vertex_slots(element_vertices: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """CSR vertex -> element corners: ``slots[voffsets[v]:voffsets[v+1]]`` are the
    ``element * 3 + corner`` of vertex v, ascending."""
    flat = np.asarray(element_vertices, np.int64).reshape(-1)
    order = np.argsort(flat, kind="stable")
    voffsets = np.concatenate([[0], np.cumsum(np.bincount(flat, minlength=n_vertices))]).astype(np.int64)
    return voffsets, order.astype(np.int32)


def _check_window_args(n_rows: int, n_elements: int, n_emitted, back, fwd, rows):
    n_emitted = np.asarray(n_emitted, np.float64).reshape(-1)
    back = np.ascontiguousarray(back, np.uint8)
    fwd = np.ascontiguousarray(fwd, np.uint8)
    rows = np.asarray(rows, np.int64).reshape(-1)
    if n_emitted.shape[0] != n_rows or back.shape != (len(rows), n_elements) or fwd.shape != back.shape:
        raise ValueError("sums, n_emitted, back/fwd and rows disagree in shape")
    if len(rows) and ((rows[:, None] - back < 0).any() or (rows[:, None] + fwd >= n_rows).any()):
        raise ValueError("a window reaches outside the frames of the sums table")
    return n_emitted, back, fwd, rows


def _check_windows(sums, n_emitted, back, fwd, rows):
    sums = np.ascontiguousarray(sums, np.float64)
    if sums.ndim != 5 or sums.shape[3:] != (3, 4):
        raise ValueError(f"sums must be (frames, elements, parity, 3, 4), got {sums.shape}")
    return (sums, *_check_window_args(sums.shape[0], sums.shape[1], n_emitted, back, fwd, rows))


def _flux(d_table: cl.Buffer, n_emitted, back, fwd, rows, element_vertices, n_vertices: int, n_elements: int,
          n_parity: int, linear: bool) -> np.ndarray:
    """Steps 2 and 3 from an element-major device prefix table (E, len(n_emitted) + 1, P, 12),
    all output frames in one launch."""
    ctx, queue = device_context()
    # Vertex-major on the device: the frames of one vertex are neighbouring work items and writes
    if len(rows) == 0 or n_elements == 0 or n_vertices == 0:
        return np.moveaxis(np.zeros((n_vertices, len(rows), n_parity, 4)), 0, 2)
    out = np.empty((n_vertices, len(rows), n_parity, 4))
    cum_n = np.concatenate([[0.0], np.cumsum(n_emitted)])
    g = np.arange(len(n_emitted), dtype=np.float64)  # prefix sums of g N_g and g^2 N_g: linear windows' moments
    cum_gn = np.concatenate([[0.0], np.cumsum(g * n_emitted)])
    cum_ggn = np.concatenate([[0.0], np.cumsum(g * g * n_emitted)])
    voffsets, slots = vertex_slots(element_vertices, n_vertices)
    d_out = scratch("gather.vertex_flux", out.nbytes)
    back_t, fwd_t = (np.ascontiguousarray(a.T) for a in (back, fwd))  # (E, n_out)
    kernel("gather", "vertex_window_flux")(
        queue, (n_vertices,), None, d_table, _upload(ctx, cum_n), _upload(ctx, cum_gn), _upload(ctx, cum_ggn),
        _upload(ctx, back_t), _upload(ctx, fwd_t),
        _upload(ctx, rows.astype(np.int32)), _upload(ctx, voffsets), _upload(ctx, slots), np.int32(n_vertices),
        np.int32(n_elements), np.int32(n_parity), np.int32(len(n_emitted) + 1), np.int32(len(rows)),
        np.int32(bool(linear)), d_out)
    cl.enqueue_copy(queue, out, d_out)
    return np.moveaxis(out, 0, 2)  # (n_out, P, V, 4), a view


def frame_sums_flux_cl(frame_sums: Iterable[npt.ArrayLike], n_emitted: npt.ArrayLike, back: npt.ArrayLike,
                       fwd: npt.ArrayLike, rows: npt.ArrayLike, element_vertices: npt.ArrayLike,
                       n_vertices: int, *, linear: bool = False) -> np.ndarray:
    """Steps 2-3 on PoCL from per-frame element sums made earlier: what lets pipeline/collection/maps.py sum
    a frame's records once per worker, however many chunks' windows reach it. The prefix table is
    filled one launch a frame from the arrays where they lie (no host stacking or transposition),
    then window sums and vertices in one launch.

    Parameters
    ----------
    frame_sums : J arrays (E, P, 3, 4), each :func:`element_sums_cl` of one of J consecutive frames.
    n_emitted : (J,) photons emitted in each of those frames.
    back, fwd : (n_out, E) windows of the output frames (kernels/temporal.py).
    rows : (n_out,) row of each output frame among the J frames.
    element_vertices : (E, 3) vertex ids; ``n_vertices`` V.
    linear : each element corner's value is its window's linear fit at the frame, the slope shrunk
        by its photon noise (docs/05-estimators.md §1.6), instead of the window's pooled mean.

    Returns
    -------
    (n_out, P, V, 4) float64: RGB ``S_v`` (energy / photons emitted) and the variance term
    (pooled mean: ``sum b^2 Y^2 / N^2``). Irradiance is ``S_v / A_v`` (:func:`irradiance`). NumPy
    twin: :func:`window_flux_reference` of the stacked sums.
    """
    frame_sums = [np.ascontiguousarray(a, np.float64) for a in frame_sums]
    n_rows = len(frame_sums)
    if not n_rows:
        raise ValueError("no frames of sums to gather")
    n_elements, n_parity = frame_sums[0].shape[:2]
    if any(a.shape != (n_elements, n_parity, 3, 4) for a in frame_sums):
        raise ValueError(f"frame sums must all be (elements, parity, 3, 4), got {frame_sums[0].shape} and others")
    n_emitted, back, fwd, rows = _check_window_args(n_rows, n_elements, n_emitted, back, fwd, rows)
    width = n_elements * n_parity * SLOTS
    if width == 0:
        return np.zeros((len(rows), n_parity, n_vertices, 4))
    ctx, queue = device_context()
    d_table = scratch("gather.table", 8 * (n_rows + 1) * width)
    step = kernel("gather", "frame_sums_prefix_step")
    held = []  # read in place: keep the buffers until the kernels have finished
    for j, a in enumerate(frame_sums):
        held.append(_in_place(ctx, a))
        step(queue, (n_elements * n_parity,), None, held[-1], np.int32(j), np.int32(n_rows),
             np.int32(n_elements), np.int32(n_parity), d_table)
    queue.finish()
    del held
    return _flux(d_table, n_emitted, back, fwd, rows, element_vertices, n_vertices, n_elements, n_parity, linear)


def window_flux_reference(sums: npt.ArrayLike, n_emitted: npt.ArrayLike, back: npt.ArrayLike, fwd: npt.ArrayLike,
                          rows: npt.ArrayLike, element_vertices: npt.ArrayLike, n_vertices: int, *,
                          linear: bool = False) -> np.ndarray:
    """NumPy twin of :func:`frame_sums_flux_cl` (``sums`` (J, E, P, 3, 4): its ``frame_sums``
    stacked): window rows added directly, corners scattered with ``np.bincount``."""
    sums, n_emitted, back, fwd, rows = _check_windows(sums, n_emitted, back, fwd, rows)
    n_rows, n_elements, n_parity = sums.shape[:3]
    ev = np.asarray(element_vertices, np.int64).reshape(n_elements, 3)
    out = np.zeros((len(rows), n_parity, n_vertices, 4))
    per_parity = n_emitted / n_parity
    for i, row in enumerate(rows):
        lo, hi = row - back[i].astype(np.int64), row + fwd[i].astype(np.int64) + 1
        total = np.zeros((n_elements, n_parity, 3, 4))
        # photons; with ``linear`` also the moments of x = g - row: photons' first and second,
        # the sums' first (RGB) and Q's first and second
        n, x1, x2 = (np.zeros(n_elements) for _ in range(3))
        s1 = np.zeros((n_elements, n_parity, 3, 3))
        q1, q2 = np.zeros((n_elements, n_parity, 3)), np.zeros((n_elements, n_parity, 3))
        for g in range(int(lo.min(initial=row)), int(hi.max(initial=row + 1))):
            inside = (lo <= g) & (g < hi)
            x = float(g - row)
            total[inside] += sums[g, inside]
            n[inside] += per_parity[g]
            if linear:
                x1[inside] += per_parity[g] * x
                x2[inside] += per_parity[g] * x * x
                s1[inside] += x * sums[g, inside, ..., :3]
                q1[inside] += x * sums[g, inside, ..., 3]
                q2[inside] += (x * x) * sums[g, inside, ..., 3]
        if linear:
            total = _linear_windows(total, n, x1, x2, s1, q1, q2)
        else:
            total[..., :3] /= n[:, None, None, None]
            total[..., 3] /= (n * n)[:, None, None]
        for p in range(n_parity):
            out[i, p] = corners_to_vertices(total[:, p], ev, n_vertices)
    return out


def corners_to_vertices(corners: np.ndarray, element_vertices: np.ndarray, n_vertices: int) -> np.ndarray:
    """(V, C) the sum, at each vertex, of the values (E, 3, C) of the element corners that are that
    vertex (docs/05-estimators.md §1.2: S_v sums b_k x energy over the hits of every element at v)."""
    ev = np.asarray(element_vertices).reshape(-1)
    out = np.empty((int(n_vertices), corners.shape[-1]))
    for c in range(corners.shape[-1]):
        out[:, c] = np.bincount(ev, weights=corners[:, :, c].reshape(-1), minlength=int(n_vertices))
    return out


def _linear_windows(total: np.ndarray, n: np.ndarray, x1: np.ndarray, x2: np.ndarray, s1: np.ndarray,
                    q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """``linear_window`` of gather.cl for every element corner: (E, P, 3, 4) window sums and the
    window's moments (``n``, ``x1``, ``x2`` (E,) photons; ``s1`` (E, P, 3, 3), ``q1``, ``q2``
    (E, P, 3)) -> (R, G, B) per photon at the frame and the variance term."""
    xb = (x1 / n)[:, None, None]
    sxx = (x2 - x1 * x1 / n)[:, None, None]
    fit = np.broadcast_to(sxx > 1e-9 * n[:, None, None], total.shape[:3])
    safe = np.where(fit, sxx, 1.0)
    beta = (s1 - xb[..., None] * total[..., :3]) / safe[..., None]
    var_b = np.maximum(q2 - 2.0 * xb * q1 + xb * xb * total[..., 3], 0.0) / (safe * safe)
    by = beta @ np.asarray(LUMA)
    lam = np.where(fit & (by * by > var_b), 1.0 - var_b / np.where(by != 0, by * by, 1.0), 0.0)
    out = np.empty_like(total)
    out[..., :3] = np.maximum(total[..., :3] / n[:, None, None, None] - (xb * lam)[..., None] * beta, 0.0)
    out[..., 3] = total[..., 3] / (n * n)[:, None, None] + xb * xb * lam * lam * np.where(fit, var_b, 0.0)
    return out


def irradiance(flux: np.ndarray, vertex_areas: np.ndarray) -> np.ndarray:
    """E_v = S_v / A_v (docs/05-estimators.md §1.2), RGB, for vertex flux ``(..., V, 4)``; 0 where A_v = 0."""
    areas = np.asarray(vertex_areas, np.float64)
    safe = np.where(areas > 0, areas, 1.0)
    return np.where((areas > 0)[..., None], flux[..., :3] / safe[..., None], 0.0)
