"""Temporal photon collection windows per (frame, element): Condition (1) of §5.1.

For frame ``f`` and element ``e`` the window is ``[f - back, f + fwd]``: the frames whose photons
reconstruct ``e``'s lighting at ``f`` (§5.1, §5.2.4). Input is the frames x elements hit-count
table the photon store keeps (§4), never the records.

Condition (1), as implemented (paper symbols; ``s`` = ``smoothing_frames``, default 3)::

    R(g)  = mean over j in S(g) of c_j / N_j        S(g): s frames centred on g, clipped at the ends
    mu    = N_f R(f)                                 mean count at f ("three subsequent frames")
    x(g)  = N_f R(g)                                 same-width mean at the candidate frame g
    sigma = sqrt(mu N_f Q(g)),  Q(g) = mean over j in S(g) of 1 / N_j;  sigma = 1 where mu = 0
    keep g while  mu - k sigma <= x(g) <= mu + k sigma,  evaluated as (x - mu)^2 <= k^2 sigma^2

Walks run backward and forward from f independently and stop at the first failing frame, at
F_max/2 frames and at the animation's ends. Afterwards at least ``min_extent`` frames are taken:
the paper's minimal extent of 3 frames, justified by temporal masking (§5.1). The paper does not
say where the extra frames lie. ``similar=True`` (``RenderConfig.min_extent_similar``, default off since the
regional step test, pipeline/regional_steps.py, stops windows at abrupt changes itself):
where the walks cover fewer than ``min_extent`` frames, the missing ones are placed on the side(s)
least unlike f, by the summed z^2 of the added frames, z^2(g) = (r_g - r_f)^2 N_f N_g / (c_f + c_g)
(r = c/N, the Poisson z-score of a common rate), but only if that beats the most centred placement
by more than k^2 (k of Eq. (1)), so noise alone mostly keeps the centred one (choosing by similarity to f's own
noisy count pulls the estimate towards that noise); where the walks already cover ``min_extent``
frames they stay as walked. Cost where nothing jumps, ROOM's K_1 at 640,000 photons a frame
against a 64,000,000-photon reference: rel L2 0.0205 against 0.0200 centred, d_AQM 2.95 % against
2.94 % (0.0206 and 2.96 % ungated). Why: beside an abrupt change (a light switched at frame J)
the 3-frame means put a third of the change into mu at J-1 and J, so both walks stop at once
there, and a centred extent pooled frame J into J-1 and J-1 into J: a third of the wrong lighting
for two frames, and a flicker the error benchmark (pipeline/benchmarks/error.py) measured as half
of the guided run's. With the placement, J-1 takes
[J-3, J-1] and J takes [J, J+2]. ``similar=False``, or where no placement fits the limits: at
least ``(min_extent-1)//2`` back and the rest forward, each clipped to F_max/2 and the ends.

The two walks end apart, as in the paper: an asymmetric window's drift bias is taken out by the
linear windows of the gather (docs/estimators.md §1.6), not by cutting the longer walk.

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


def _check(counts, n_emitted, fmax, mode, smoothing_frames, min_extent, frames):
    counts = np.ascontiguousarray(counts, dtype=np.uint32)
    if counts.ndim != 2:
        raise ValueError(f"counts must be (frames, elements), got shape {counts.shape}")
    n_frames = counts.shape[0]
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
    return counts, n_emitted, f0, f1


def inverse_budget(n_emitted: np.ndarray, smoothing_frames: int) -> np.ndarray:
    """Q(g): mean of 1/N_j over the smoothing frames of g (float64, j ascending)."""
    n_emitted = np.asarray(n_emitted, dtype=np.float64)
    n_frames, half = n_emitted.shape[0], smoothing_frames // 2
    q = np.empty(n_frames)
    for g in range(n_frames):
        lo, hi = max(0, g - half), min(n_frames - 1, g + half)
        total = 0.0
        for j in range(lo, hi + 1):
            total += 1.0 / n_emitted[j]
        q[g] = total / (hi - lo + 1)
    return q


def _extents(fmax: int, mode: str, min_extent: int) -> tuple[int, int, int, bool]:
    half_fmax = 0 if mode == "off" else int(fmax) // 2
    half_lo = (min_extent - 1) // 2
    return half_fmax, half_lo, min_extent - 1 - half_lo, mode == "adaptive"


def windows_cl(counts: npt.ArrayLike, n_emitted: npt.ArrayLike, *, fmax: int, mode: str = "adaptive",
               k_sigma: float = 2.0, smoothing_frames: int = 3, min_extent: int = 3, similar: bool = True,
               frames: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Windows of frames ``[f0, f1)`` (default all) on PoCL.

    Parameters
    ----------
    counts : (F, E) uint32 hit counts per frame and element (the store's count table).
    n_emitted : (F,) photons emitted per frame, N_frame.
    fmax : F_max, the segment length; each direction is limited to F_max // 2 frames.
    similar : where the minimal extent's extra frames go (module docstring).
    frames : optional (f0, f1) range of output frames (indices into the table).

    Returns
    -------
    back, fwd : (f1 - f0, E) uint8, the window of frame f is [f - back, f + fwd].
    """
    counts, n_emitted, f0, f1 = _check(counts, n_emitted, fmax, mode, smoothing_frames, min_extent, frames)
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
    d_q = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=inverse_budget(n_emitted, smoothing_frames))
    d_rate = cl.Buffer(ctx, mf.READ_WRITE, size=8 * counts.size)
    d_counts = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=counts if adaptive else np.zeros(1, np.uint32))
    if adaptive:
        kernel("temporal", "smooth_rates")(
            queue, (counts.size,), None, d_counts, d_n, np.int32(n_frames), np.int32(n_elements),
            np.int32(smoothing_frames // 2), d_rate)
    d_back = cl.Buffer(ctx, mf.WRITE_ONLY, size=back.nbytes)
    d_fwd = cl.Buffer(ctx, mf.WRITE_ONLY, size=fwd.nbytes)
    kernel("temporal", "windows")(
        queue, (back.size,), None, d_rate, d_counts, d_n, d_q, np.int32(n_frames), np.int32(n_elements),
        np.int32(f0), np.int32(n_out), np.int32(half_fmax), np.int32(half_lo), np.int32(half_hi),
        np.float64(float(k_sigma) * float(k_sigma)), np.int32(adaptive), np.int32(bool(similar)), d_back, d_fwd)
    cl.enqueue_copy(queue, back, d_back)
    cl.enqueue_copy(queue, fwd, d_fwd)
    return back, fwd


def smoothed_rates_reference(counts: np.ndarray, n_emitted: np.ndarray, smoothing_frames: int) -> np.ndarray:
    """R(g, e): mean of c_j / N_j over the smoothing frames of g (float64, j ascending)."""
    n_frames = counts.shape[0]
    half = smoothing_frames // 2
    rate = np.empty(counts.shape)
    for g in range(n_frames):
        lo, hi = max(0, g - half), min(n_frames - 1, g + half)
        total = np.zeros(counts.shape[1])
        for j in range(lo, hi + 1):
            total = total + counts[j].astype(np.float64) / n_emitted[j]
        rate[g] = total / float(hi - lo + 1)
    return rate


def windows_reference(counts: npt.ArrayLike, n_emitted: npt.ArrayLike, *, fmax: int, mode: str = "adaptive",
                      k_sigma: float = 2.0, smoothing_frames: int = 3, min_extent: int = 3, similar: bool = True,
                      frames: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """NumPy twin of :func:`windows_cl` (same arguments and results)."""
    counts, n_emitted, f0, f1 = _check(counts, n_emitted, fmax, mode, smoothing_frames, min_extent, frames)
    n_frames, n_elements = counts.shape
    half_fmax, half_lo, half_hi, adaptive = _extents(fmax, mode, min_extent)
    back = np.zeros((f1 - f0, n_elements), np.uint8)
    fwd = np.zeros((f1 - f0, n_elements), np.uint8)
    if adaptive:
        rate = smoothed_rates_reference(counts, n_emitted, smoothing_frames)
        q = inverse_budget(n_emitted, smoothing_frames)
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
        span = half_lo + half_hi  # frames besides f the minimal extent needs
        placed = _place_similar(counts, n_emitted, f, b, w, span, max_back, max_fwd, k2) if similar \
            else np.full(n_elements, -1)
        back[i] = np.where(placed >= 0, placed, np.maximum(b, min(half_lo, max_back)))
        fwd[i] = np.where(placed >= 0, np.where(b + w >= span, w, span - placed),
                          np.maximum(w, min(half_hi, max_fwd)))
    return back, fwd


def _unlike(counts: np.ndarray, n_emitted: np.ndarray, e: int, f: int, g: int) -> float:
    """z^2 of r_g - r_f of element e under one common rate (temporal.cl ``unlike``)."""
    s = float(counts[f, e]) + float(counts[g, e])
    if s == 0.0:
        return 0.0
    d = float(counts[g, e]) / n_emitted[g] - float(counts[f, e]) / n_emitted[f]
    return d * d * (n_emitted[f] * n_emitted[g]) / s


def _place_similar(counts: np.ndarray, n_emitted: np.ndarray, f: int, b: np.ndarray, w: np.ndarray, span: int,
                   max_back: int, max_fwd: int, k2: float) -> np.ndarray:
    """Per element, the back extent of the minimal extent's placement (module docstring): the walked
    one where the walks cover ``span`` frames besides f, -1 where no placement fits the limits;
    scalar loops in the kernel's order, so the sums round alike."""
    out = np.where(b + w >= span, b, -1).astype(np.int64)
    for e in np.flatnonzero(b + w < span):
        b_e, w_e = int(b[e]), int(w[e])
        need = span - b_e - w_e
        best_b, centre_b, centre_skew, best, centre = -1, -1, 0, 0.0, 0.0
        for more in range(need + 1):
            nb, nw = b_e + more, w_e + need - more
            if nb > max_back or nw > max_fwd:
                continue
            cost = 0.0
            for j in range(b_e + 1, nb + 1):
                cost += _unlike(counts, n_emitted, e, f, f - j)
            for j in range(w_e + 1, nw + 1):
                cost += _unlike(counts, n_emitted, e, f, f + j)
            if best_b < 0 or cost < best:
                best_b, best = nb, cost
            skew = abs(nb - nw)
            if centre_b < 0 or skew < centre_skew:
                centre_b, centre, centre_skew = nb, cost, skew
        if centre_b >= 0:
            out[e] = best_b if centre - best > k2 else centre_b
    return out
