"""Temporal photon collection windows per (frame, element): Condition (1) of §5.1.

For frame ``f`` and element ``e`` the window is ``[f - back, f + fwd]``: the frames whose photons
reconstruct ``e``'s lighting at ``f`` (§5.1, §5.2.4). Input is the frames x elements hit-count
table the photon store keeps (§4), never the records.

Condition (1), as implemented (paper symbols; ``s`` = ``smoothing_frames``, default 3)::

    R(g)  = mean over j in S(g) of c_j / N_j        S(g): s frames centred on g, clipped at the ends
                                                     and at the element's lighting steps
    mu    = N_f R(f)                                 mean count at f ("three subsequent frames")
    x(g)  = N_f R(g)                                 same-width mean at the candidate frame g
    sigma = sqrt(mu N_f Q(g)),  Q(g) = mean over j in S(g) of 1 / N_j;  sigma = 1 where mu = 0
    keep g while  mu - k sigma <= x(g) <= mu + k sigma,  evaluated as (x - mu)^2 <= k^2 sigma^2

Walks run backward and forward from f independently and stop at the first failing frame, at
F_max/2 frames and at the animation's ends. Afterwards at least ``min_extent`` frames are taken:
the paper's minimal extent of 3 frames, justified by temporal masking (§5.1). The paper does not
say where the extra frames lie; they are centred: at least ``(min_extent-1)//2`` back and the rest
forward, each clipped to F_max/2 and the ends. Beside an abrupt change the regional step test
(pipeline/collection/regional_steps.py) keeps a frame's window to its own side; placing the extra frames on
the side least unlike the frame was tried and removed (docs/11-defaults.md, "min_extent_similar").

Lighting steps (``cuts``, from the regional step test) also clip the means R and Q, as the ends do:
a three-frame mean taken across a step is one third of the other side's lighting, so at the frames
on either side of a step mu stood apart from every frame of the frame's own side and Condition (1)
stopped both walks at once (docs/06-temporal.md §3).

The two walks end apart, as in the paper: an asymmetric window's drift bias is taken out by the
linear windows of the gather (docs/05-estimators.md §1.6), not by cutting the longer walk.

Different N_frame in neighbouring frames (N doubles per segment in §5.2.3). Counts are compared on
frame f's photon budget: a count c_j is scaled by N_f / N_j (done as N_f * (c_j / N_j)). Under
unchanged lighting the scaled count has mean mu and variance mu N_f / N_j, so sigma^2 = mu N_f Q(g):
a frame that shot half of f's photons has counts noisier by sqrt(2) once scaled, and one that
shot twice as many is quieter by sqrt(2). With equal N everywhere sigma = sqrt(mu), the paper's
Poisson sigma. The paper's sigma = sqrt(mu) is the single-frame Poisson deviation even though x and
mu are 3-frame means; we keep that convention (it makes the test looser, as the paper wants for
the noisy estimates of mu at early convergence).

Modes: ``"adaptive"`` (above), ``"fixed"`` (always +-F_max/2, the non-adaptive collection of §6,
Fig. 3b, 4a), ``"off"`` (the frame alone).

Both the OpenCL kernel (``temporal.cl``) and the NumPy twin compute in double with the same order
of operations and no fused multiply-add, so their windows are identical.
"""
from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pyopencl as cl

from .context import device_context, kernel

MODES = ("adaptive", "fixed", "off")
MAX_HALF_FMAX = 255  # back and fwd are stored as uint8


def _check(counts, n_emitted, fmax, mode, smoothing_frames, min_extent, frames, cuts):
    counts = np.ascontiguousarray(counts, dtype=np.uint32)
    if counts.ndim != 2:
        raise ValueError(f"counts must be (frames, elements), got shape {counts.shape}")
    n_frames = counts.shape[0]
    padded = np.zeros(counts.shape, np.uint8)  # row t: a step between frames t and t + 1; the last row none
    if cuts is not None:
        cuts = np.asarray(cuts)
        if cuts.shape != (max(n_frames - 1, 0), counts.shape[1]):
            raise ValueError(f"cuts must be (frames - 1, elements) = {(max(n_frames - 1, 0), counts.shape[1])}, "
                             f"got {cuts.shape}")
        padded[:n_frames - 1] = cuts != 0
    n_emitted = np.ascontiguousarray(n_emitted, dtype=np.float64).reshape(-1)
    if n_emitted.shape[0] != n_frames:
        raise ValueError(f"n_emitted has {n_emitted.shape[0]} frames, counts {n_frames}")
    if n_frames and not (n_emitted > 0).all():
        raise ValueError("every frame of the count table needs photons (N_frame > 0)")
    if mode not in MODES:
        raise ValueError(f"temporal mode must be one of {', '.join(MODES)}, got {mode!r}")
    if not 0 <= int(fmax) <= 2 * MAX_HALF_FMAX:
        raise ValueError(f"F_max must be in [0, {2 * MAX_HALF_FMAX}], got {fmax}")
    if smoothing_frames < 1 or smoothing_frames % 2 == 0 or min_extent < 1:
        raise ValueError("smoothing_frames must be odd and >= 1, min_extent >= 1")
    f0, f1 = (0, n_frames) if frames is None else (int(frames[0]), int(frames[1]))
    if not 0 <= f0 <= f1 <= n_frames:
        raise ValueError(f"frames [{f0}, {f1}) outside the table's {n_frames} frames")
    return counts, n_emitted, f0, f1, padded


def _extents(fmax: int, mode: str, min_extent: int) -> tuple[int, int, int, bool]:
    half_fmax = 0 if mode == "off" else int(fmax) // 2
    half_lo = (min_extent - 1) // 2
    return half_fmax, half_lo, min_extent - 1 - half_lo, mode == "adaptive"


def windows_cl(counts: npt.ArrayLike, n_emitted: npt.ArrayLike, *, fmax: int, mode: str = "adaptive",
               k_sigma: float = 2.0, smoothing_frames: int = 3, min_extent: int = 3,
               frames: tuple[int, int] | None = None,
               cuts: npt.ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Windows of frames ``[f0, f1)`` (default all) on PoCL.

    Parameters
    ----------
    counts : (F, E) uint32 hit counts per frame and element (the store's count table).
    n_emitted : (F,) photons emitted per frame, N_frame.
    fmax : F_max, the segment length; each direction is limited to F_max // 2 frames.
    frames : optional (f0, f1) range of output frames (indices into the table).
    cuts : optional (F - 1, E) bool, the element's lighting steps between frames t and t + 1: the
        smoothed means do not cross them (the walks are cut there by the caller).

    Returns
    -------
    back, fwd : (f1 - f0, E) uint8, the window of frame f is [f - back, f + fwd].
    """
    counts, n_emitted, f0, f1, cuts = _check(counts, n_emitted, fmax, mode, smoothing_frames, min_extent, frames,
                                             cuts)
    n_frames, n_elements = counts.shape
    n_out = f1 - f0
    back = np.zeros((n_out, n_elements), np.uint8)
    fwd = np.zeros((n_out, n_elements), np.uint8)
    if n_out == 0 or n_elements == 0:
        return back, fwd
    half_fmax, half_lo, half_hi, adaptive = _extents(fmax, mode, min_extent)
    ctx, queue = device_context()
    mf = cl.mem_flags
    d_n = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=n_emitted)
    d_rate = cl.Buffer(ctx, mf.READ_WRITE, size=8 * counts.size)
    d_q = cl.Buffer(ctx, mf.READ_WRITE, size=8 * counts.size)
    if adaptive:
        d_counts = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=counts)
        d_cuts = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=cuts)
        kernel("temporal", "smooth_rates")(
            queue, (counts.size,), None, d_counts, d_n, d_cuts, np.int32(n_frames), np.int32(n_elements),
            np.int32(smoothing_frames // 2), d_rate, d_q)
    d_back = cl.Buffer(ctx, mf.WRITE_ONLY, size=back.nbytes)
    d_fwd = cl.Buffer(ctx, mf.WRITE_ONLY, size=fwd.nbytes)
    kernel("temporal", "windows")(
        queue, (back.size,), None, d_rate, d_n, d_q, np.int32(n_frames), np.int32(n_elements),
        np.int32(f0), np.int32(n_out), np.int32(half_fmax), np.int32(half_lo), np.int32(half_hi),
        np.float64(float(k_sigma) * float(k_sigma)), np.int32(adaptive), d_back, d_fwd)
    cl.enqueue_copy(queue, back, d_back)
    cl.enqueue_copy(queue, fwd, d_fwd)
    return back, fwd


def smoothed_rates_reference(counts: np.ndarray, n_emitted: np.ndarray, smoothing_frames: int,
                             cuts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R(g, e), the mean of c_j / N_j, and Q(g, e), the mean of 1/N_j, over the smoothing frames of g
    clipped at the ends and at the element's steps (``cuts`` (F, E), row t: between t and t + 1);
    float64, j ascending."""
    n_frames, n_elements = counts.shape
    half = smoothing_frames // 2
    rate = np.empty(counts.shape)
    q = np.empty(counts.shape)
    cut = np.asarray(cuts, bool)
    for g in range(n_frames):
        lo = np.full(n_elements, g, np.int64)
        hi = np.full(n_elements, g, np.int64)
        open_lo = np.ones(n_elements, bool)
        open_hi = np.ones(n_elements, bool)
        for d in range(1, half + 1):
            if g - d >= 0:
                open_lo &= ~cut[g - d]
                lo = np.where(open_lo, g - d, lo)
            if g + d < n_frames:
                open_hi &= ~cut[g + d - 1]
                hi = np.where(open_hi, g + d, hi)
        total = np.zeros(n_elements)
        inv = np.zeros(n_elements)
        for j in range(max(0, g - half), min(n_frames - 1, g + half) + 1):
            inside = (lo <= j) & (j <= hi)
            total = np.where(inside, total + counts[j].astype(np.float64) / n_emitted[j], total)
            inv = np.where(inside, inv + 1.0 / n_emitted[j], inv)
        width = (hi - lo + 1).astype(np.float64)
        rate[g] = total / width
        q[g] = inv / width
    return rate, q


def windows_reference(counts: npt.ArrayLike, n_emitted: npt.ArrayLike, *, fmax: int, mode: str = "adaptive",
                      k_sigma: float = 2.0, smoothing_frames: int = 3, min_extent: int = 3,
                      frames: tuple[int, int] | None = None,
                      cuts: npt.ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
    """NumPy twin of :func:`windows_cl` (same arguments and results)."""
    counts, n_emitted, f0, f1, cuts = _check(counts, n_emitted, fmax, mode, smoothing_frames, min_extent, frames,
                                             cuts)
    n_frames, n_elements = counts.shape
    half_fmax, half_lo, half_hi, adaptive = _extents(fmax, mode, min_extent)
    back = np.zeros((f1 - f0, n_elements), np.uint8)
    fwd = np.zeros((f1 - f0, n_elements), np.uint8)
    if adaptive:
        rate, q = smoothed_rates_reference(counts, n_emitted, smoothing_frames, cuts)
    k2 = float(k_sigma) * float(k_sigma)
    for i, f in enumerate(range(f0, f1)):
        max_back, max_fwd = min(half_fmax, f), min(half_fmax, n_frames - 1 - f)
        if not adaptive:
            back[i], fwd[i] = max_back, max_fwd
            continue
        n_f = n_emitted[f]
        mu = n_f * rate[f]
        walked = []
        for step, limit in ((-1, max_back), (1, max_fwd)):
            extent = np.zeros(n_elements, np.int64)
            alive = np.ones(n_elements, bool)
            for d in range(1, limit + 1):
                g = f + step * d
                d = n_f * rate[g] - mu
                var = np.where(mu > 0.0, mu * (n_f * q[g]), 1.0)
                ok = d * d <= k2 * var  # mu - k sigma <= x <= mu + k sigma
                alive &= ok
                extent += alive
            walked.append(extent)
        b, w = walked
        back[i] = np.maximum(b, min(half_lo, max_back))
        fwd[i] = np.maximum(w, min(half_hi, max_fwd))
    return back, fwd

