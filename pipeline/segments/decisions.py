"""The pure decisions of the segments (§5.2): arrays and numbers in, decisions out.

Nothing here touches Dask, zarr or files, so every rule is tested on synthetic inputs with known
answers (tests/coordinator/test_segments.py); the planner (pipeline/segments/planner.py) only runs them.

* :func:`energy_error`, :func:`pilot_n_frame` — Step 1 (§5.2.1, Eq. 2);
* :func:`p_me`, :func:`grow_fmax` — Step 2 (§5.2.2);
* :func:`ladder_n_frame`, :func:`next_n_frame` — Step 3 (§5.2.3; the ladder is ours), one doubling a
  step as the paper's; :func:`doublings_ahead` extrapolates what a capped segment still lacked;
  :func:`unlit_n_frame` starts a segment whose pilot saw no indirect light;
* :func:`place_segment`, :func:`photon_targets` — where segments lie and how many photons each
  frame gets (the first and last segments compensate their missing neighbour, §5.2);
* :func:`lighting_steps`, :func:`keyframe_off_steps` — a segment an abrupt lighting change divides
  is judged away from it, and the frames beside it are compensated as the ends are (ours,
  docs/07-segments.md §8); :func:`lit_keyframe` — a segment is judged where its light is.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Iterable

import numpy as np


# --- Step 1: initialization (§5.2.1) -----------------------------------------------------------
def energy_error(s_y: np.ndarray, q_y: np.ndarray) -> float:
    """The energy-based error E of an indirect illumination map (docs/05-estimators.md §1.4), as a fraction.

    E = sum_v A_v sigma_v / sum_v A_v E_v, the flux-weighted mean relative standard error of the
    vertex values, with E_v = S_v / A_v and sigma_v = sqrt(Q_v) / A_v (docs/05-estimators.md §1.3: the variance
    of a sum of i.i.d. photon weights is estimated by the sum of their squares). The areas cancel:
    E = sum sqrt(Q_v) / sum S_v. ``s_y`` (V,) luminance flux per vertex, ``q_y`` (V,) its sum of
    squared weights. Why this estimate: it is scale-free, dominated by the bright regions a
    viewer adapts to, ignores unlit vertices and falls exactly as 1/sqrt(N) (Eq. 2's premise);
    it is measured on the unfiltered vertex values, the map Condition (1) pools in time, so the
    target E_max sqrt(F_max + 1) speaks of the photons before any spatial filter (Step 5 repairs
    only what the AQM still sees). Returns inf when the map holds no light.
    """
    total = float(np.sum(s_y, dtype=np.float64))
    if not total > 0:
        return math.inf
    return float(np.sum(np.sqrt(np.maximum(q_y, 0.0)), dtype=np.float64)) / total


def pilot_n_frame(n_probe: int, e_probe: float, e_max: float, fmax: int) -> float:
    """N_frame from a pilot run of ``n_probe`` photons with error ``e_probe`` (§5.2.1, Eq. 2).

    The pilot runs "until E ~ E_max sqrt(F_max + 1)"; since E is proportional to 1/sqrt(N)
    (Eq. 2, [15]), the photons that reach that error follow from one probe without running on:
    N_frame = n_probe (e_probe / (E_max sqrt(F_max + 1)))^2. Pooling F_max + 1 frames of N_frame
    photons then gives E ~ E_max.
    """
    if not (n_probe > 0 and e_max > 0 and fmax >= 0):
        raise ValueError(f"pilot_n_frame({n_probe}, {e_probe}, {e_max}, {fmax})")
    target = e_max * math.sqrt(fmax + 1)
    return n_probe * (e_probe / target) ** 2


def calibrated_start(n_pilot: float, previous: tuple[float, float] | None) -> float:
    """Where Step 3 starts for a segment: the pilot's N_frame (Eq. 2) times what the previous
    segment's doubling loop found the energy criterion to under-ask, halved.

    ``previous`` is (its pilot's N_frame, its final N_frame). The paper starts every segment at its
    pilot's guess; when our AQM asks 2^k times more (on ROOM, 25-100x), every segment would double
    k times again, each step an AQM evaluation and a pass over the segment's photons. The pilot
    still measures this segment's E, so a segment lit differently moves with it; starting one
    doubling below the carried-over ratio lets a segment that needs less stop lower than its
    predecessor did. Without a previous segment, or a ratio under 2, it is the paper's rule.
    """
    if previous is None or not (previous[0] and previous[0] > 0 and math.isfinite(n_pilot)):
        return n_pilot
    return n_pilot * max(1.0, previous[1] / previous[0] / 2.0)


def unlit_n_frame(n_frame: int, lit_elements: int, n_max: int) -> int:
    """Step 3's first N_frame for a segment whose pilot at K recorded no indirect light, so Eq. (2)
    has no E to go on (ours, not the paper's).

    The planner starts such a segment on the smallest rung; Step 2 traces its frames there. If no
    photon of them recorded indirect light either (``lit_elements`` 0), the segment has none to
    speak of: it stays on ``n_frame`` and Step 3's AQM confirms it at the fewest photons (a flat
    skinned strip under the sun: the cap, 1,280,000 photons a frame, for halves that were both
    black). If some did, the planner moves K to a lit frame (:func:`lit_keyframe`) and pilots
    there; only where that pilot too sees nothing (its few photons miss what Step 2's found) does
    the segment take the cap ``n_max``, as it would without a pilot.
    """
    return int(n_frame) if lit_elements == 0 else int(n_max)


def needed_n_frame(n_frame: int, steps: list[dict], capped: bool, d_thr: float) -> float:
    """The N_frame a decided segment needed, for :func:`calibrated_start`: its final N_frame, or,
    when the cap (n_frame_max, §5.2.3) stopped its loop above d_thr, the cap times the doublings it
    still lacked at least (:func:`doublings_ahead` over its last two steps; ours, not the paper's).

    Why: a capped segment's final N_frame understates its need. Carried over as it is, halved, it
    started ROOM's next segments one rung below the cap at a 160,000 cap, though the previous
    segment's d_AQM there was 26-33 % against d_thr 3 %. Each then spent an AQM and a second photon
    batch a frame, only to reach the cap (docs/07-segments.md §2).
    """
    if not capped or not steps:
        return float(n_frame)
    now = (int(steps[-1]["n_frame"]), steps[-1]["d_aqm"] / 100.0)
    # one step: no fall to extrapolate, and doublings_ahead's own rule for that gives one doubling
    before = (int(steps[-2]["n_frame"]), steps[-2]["d_aqm"] / 100.0) if len(steps) > 1 else now
    return float(n_frame) * 2.0 ** doublings_ahead(before, now, d_thr)


def ladder_n_frame(n: float, n_min: int, n_max: int) -> int:
    """Step 3's first N_frame: the rung n_max / 2^k nearest to ``n`` in log, inside [n_min, n_max]
    (inf -> n_max).

    Why a ladder of the cap: doubling from anywhere else ends in a sliver step. ROOM's last segment
    went 78,071 -> 156,142 -> 160,000, a batch of 3,858 photons a frame and an AQM that told
    nothing new. From a rung every doubling lands on one and the last on the cap, and segments
    trace batches of the same sizes. The nearest rung in log moves the pilot's guess by at most
    sqrt(2) either way, so it costs no photons on average.
    """
    if not math.isfinite(n):
        return int(n_max)
    k = max(0, round(math.log2(n_max / max(float(n), 1.0))))
    while k > 0 and math.ceil(n_max / 2 ** k) < n_min:
        k -= 1
    return int(math.ceil(n_max / 2 ** k))


# --- Step 2: segment length (§5.2.2) -----------------------------------------------------------
def p_me(back: np.ndarray, fwd: np.ndarray, fmax: int, considered: np.ndarray | None = None) -> tuple[float, float]:
    """Shares of elements whose photons are collected over all F_max/2 frames before and after K.

    ``back``/``fwd`` (E,) window extents at K (kernels/temporal.py); ``considered`` (E,) bool, the
    elements that count (default all; the coordinator takes those hit by any photon in the
    segment, since an element no photon reaches keeps a full window by Condition (1)'s sigma = 1
    and would pass without telling anything about the lighting). A segment whose photons hit no
    element has no indirect light to change: (1, 1), so F_max grows and a scene without
    interreflection is judged in few, long segments.
    """
    half = fmax // 2
    back, fwd = np.asarray(back), np.asarray(fwd)
    mask = np.ones(back.shape, bool) if considered is None else np.asarray(considered, bool)
    n = int(mask.sum())
    if half == 0:
        return 0.0, 0.0
    if n == 0:  # no indirect light in the segment: none changes, every window may be full
        return 1.0, 1.0
    return float(np.count_nonzero((back >= half) & mask)) / n, float(np.count_nonzero((fwd >= half) & mask)) / n


def grow_fmax(fmax: int, p_back: float, p_fwd: float, *, p_thr: float, step: int, cap: int) -> int | None:
    """The next F_max to try, or None to keep ``fmax`` (§5.2.2).

    F_max grows while p_me >= p_thr in either direction: the paper stops "until p_me < p_thr",
    and its final K_2 (F_max = 30) has p_me below p_thr both ways (36 % and 30 %, §6). Growth is
    by ``step`` frames up to ``cap`` (15 -> 30 -> 44 with the defaults, the paper's F_max values).
    """
    if max(p_back, p_fwd) < p_thr or fmax >= cap:
        return None
    return min(fmax + step, cap)


# --- Step 3: number of photons (§5.2.3) --------------------------------------------------------
def next_n_frame(n_frame: int, d_aqm: float, d_thr: float, n_max: int) -> int | None:
    """N_frame doubled while d_AQM (a fraction of pixels) exceeds d_thr, or None to stop: at the
    first N_frame with d_AQM <= d_thr, or at the cap ``n_max`` (reported by the caller). The last
    step goes to the cap itself when doubling would pass it, so the configured maximum is reached
    whatever N_frame the pilot started from.

    One doubling a step, as §5.2.3. Several at once, extrapolated from d_AQM's fall so far
    (:func:`doublings_ahead`), were tried and removed: with the recalibrated AQM, whose d_AQM falls
    faster than the extrapolation's bound, a jump passed where plain doubling stops (ROOM's quick
    error benchmark: 1,280,000 photons a frame instead of 640,000, 1.8x the CPU), and elsewhere it
    saved nothing (docs/11-defaults.md, "predict_doublings")."""
    if d_aqm <= d_thr or n_frame >= n_max:
        return None
    return min(n_frame * 2, n_max)


def doublings_ahead(before: tuple[int, float], now: tuple[int, float], d_thr: float) -> int:
    """How many doublings of N_frame the loop of §5.2.3 needs at least from ``now`` ((N_frame,
    d_AQM)) before d_AQM <= d_thr, if d_AQM falls per doubling by at most the square of the factor
    it fell by since ``before`` (ours, not §5.2.3): :func:`needed_n_frame` of a segment the cap
    stopped. Twice the measured decline in log is the margin: the paper's "reduced by an even
    larger factor" (§5.2.3) is the noise's 1/sqrt(2) against the AQM's faster fall. One doubling
    when d_AQM did not fall (nothing to extrapolate).
    """
    (n0, d0), (n1, d1) = before, now
    if not (n1 > n0 and 0.0 < d1 < d0 and d1 > d_thr > 0.0):
        return 1
    fall = 2.0 * math.log(d1 / d0) / math.log2(n1 / n0)  # log of the steepest fall per doubling, < 0
    return max(1, math.ceil(math.log(d_thr / d1) / fall - 1e-9))


def doubling_loop(n_frame: int, measure: Callable[[int], float], *, d_thr: float,
                  n_max: int) -> tuple[int, list[dict], bool]:
    """Step 3's loop: ``measure(n)`` gives d_AQM (percent) at N_frame = n (the caller traces what
    n needs); N_frame doubles (:func:`next_n_frame`) until d_AQM <= d_thr (a fraction) or the cap.
    Returns the final N_frame, the steps [{n_frame, d_aqm}] and whether the cap stopped it above
    d_thr."""
    steps = []
    while True:
        d = float(measure(n_frame))
        steps.append({"n_frame": int(n_frame), "d_aqm": d})
        doubled = next_n_frame(n_frame, d / 100.0, d_thr, n_max)
        if doubled is None:
            return int(n_frame), steps, d / 100.0 > d_thr
        n_frame = doubled


def window_fmax_loop(fmax: int, measure: Callable[[int], float], *, d_thr: float, first: int,
                     step: int) -> tuple[int, list[dict]]:
    """The F_max of the windows that reconstruct a segment's frames: the shortest rung of Step 2's
    ladder (§5.2.2; ``first``, ``first + step``, ... below ``fmax``) at which ``measure(f)``, the halves'
    d_AQM (percent) at K with windows of F_max ``f`` at the final N_frame, is within ``d_thr`` (a
    fraction); ``fmax`` itself when none is. Returns it and the tries [{fmax, d_aqm}].

    Why: the halves see noise and not bias, and Condition (1) keeps windows longer than the
    frames' lighting allows at hundreds of thousands of photons a frame. The guided photons of
    the error benchmark collected at F_max 14 instead of Step 2's 44 are closer to the reference
    in every measure (d_AQM 0.69 against 0.93 %, rel L2 0.039 against 0.051;
    docs/07-segments.md §9), and at F_max 30 the halves still pass at the same N_frame. So of the
    windows whose noise is invisible, the shortest: the least bias for the photons traced.
    """
    tries = []
    rung = first
    while rung < fmax:
        d = float(measure(rung))
        tries.append({"fmax": int(rung), "d_aqm": d})
        if d / 100.0 <= d_thr:
            return int(rung), tries
        rung += step
    return int(fmax), tries


def fmax_loop(start: int, fmax: int, last: int, measure: Callable[[Placement], tuple[float, float]], *,
              p_thr: float, step: int, cap: int) -> tuple[Placement, list[dict]]:
    """Step 2's loop: ``measure(placement)`` gives (p_me back, p_me fwd) at its K (the caller
    traces the placement's frames); F_max grows by :func:`grow_fmax` until it stops, the cap, or
    the segment reaches the animation's end. Returns the placement and the steps."""
    place = place_segment(start, fmax, last)
    steps = []
    while True:
        pb, pf = measure(place)
        steps.append({"fmax": place.fmax, "k": place.k, "p_me_back": float(pb), "p_me_fwd": float(pf)})
        grown = grow_fmax(place.fmax, pb, pf, p_thr=p_thr, step=step, cap=cap) if place.end < last else None
        if grown is None:
            return place, steps
        place = place_segment(start, grown, last)


# --- where segments lie (§5.2, Fig. 2) ---------------------------------------------------------
@dataclass(frozen=True)
class Placement:
    """Frames [start, end] of a segment, its central frame K and its F_max."""

    start: int
    k: int
    end: int
    fmax: int

    @property
    def frames(self) -> list[int]:
        return list(range(self.start, self.end + 1))


def place_segment(start: int, fmax: int, last: int) -> Placement:
    """The segment that begins at ``start`` (the frame after the previous segment's end, §5.2.2):
    K = start + F_max/2, end = start + F_max, F_max + 1 frames.

    Near the end of the animation: a segment that would pass ``last`` ends there with K in the
    middle of what is left, and a segment that would leave fewer than F_max/2 + 1 frames after it
    takes them in (a stub shorter than half a window would get its own pilot and AQM for a few
    frames; the longer segment's windows stay bounded by F_max/2 all the same).
    """
    if fmax < 0 or start > last:
        raise ValueError(f"place_segment({start}, {fmax}, {last})")
    half = fmax // 2
    end = start + fmax
    if end >= last or last - end < half + 1:
        end = last
    k = min(start + half, (start + end) // 2) if end == last else start + half
    return Placement(start, k, end, fmax)


def end_frames(first: int, last: int, fmax: int, steps: Iterable[int] = ()) -> set[int]:
    """Frames within F_max/2 of an end of the animation, or of a lighting step (a frame ``s`` of
    ``steps`` begins after one: frames ``s - F_max/2 .. s + F_max/2 - 1``): their windows lack one
    side."""
    half = fmax // 2
    near = {f for f in range(first, last + 1) if f - first < half or last - f < half}
    for s in steps:
        near.update(f for f in range(max(first, s - half), min(last, s + half - 1) + 1))
    return near


def photon_targets(placement: Placement, n_frame: int, *, first: int, last: int, end_factor: float,
                   steps: Iterable[int] = ()) -> dict[int, int]:
    """Photons each frame of a segment traces: N_frame, and ``end_factor`` x N_frame for frames
    within F_max/2 of the animation's first or last frame (§5.2: "for the very first and last
    animation segments the lack of those extra frames is compensated by tracing more photons"),
    or of a lighting step of ``steps`` (:func:`lighting_steps`), where the windows stop as at an end.

    Why 2x by default: the end frame itself collects F_max/2 + 1 frames instead of F_max + 1,
    about half the photons, so doubling the frames it can reach restores its pooled count; the
    frames further in miss less and are over-served a little.
    """
    ends = end_frames(first, last, placement.fmax, steps)
    return {f: frame_photons(n_frame, end_factor if f in ends else 1.0) for f in placement.frames}


def lighting_steps(back: np.ndarray, considered: np.ndarray, frames: list[int], p_thr: float) -> list[int]:
    """Frames of a segment that begin after an abrupt change of the lighting: frame ``f`` (not the
    first) whose windows reach back to ``f - 1`` for fewer than ``p_thr`` of the ``considered``
    elements.

    ``back`` (F, E) window extents at ``frames`` (consecutive; kernels/temporal.py with the regional
    step test, pipeline/collection/regional_steps.py). Condition (1) keeps at least ``min_extent``
    frames, so inside steady lighting nearly every element collects its previous frame (ROOM: at
    least 96 % at every frame); only a step cuts most windows at once (ROOM's switched light: 3 %).
    p_thr is §5.2.2's share below which collecting over frames does not pay.
    """
    back = np.asarray(back)
    mask = np.asarray(considered, bool)
    n = int(mask.sum())
    if n == 0:
        return []
    return [f for i, f in enumerate(frames) if i > 0 and np.count_nonzero((back[i] >= 1) & mask) / n < p_thr]


def keyframe_off_steps(place: Placement, steps: Iterable[int], lit: Iterable[int] | None = None) -> Placement:
    """``place`` with K in the middle of its longest run of frames no lighting step divides, among
    the runs that hold a frame of ``lit`` (frames with indirect light) where any does.

    §5.2.3 judges N_frame at K and "assumes it valid for all frames in a given segment", which
    holds where the lighting changes little over the segment (§5.2.3). A K on a step is the
    segment's worst frame: its windows reach one way only. At ROOM's switched light the halves at
    K differed at 28.9 % of the pixels where 8 frames later they differed at 3.5 %, and the loop
    climbed to 1,280,000 photons a frame for the whole segment (docs/07-segments.md §8). Ties go
    to the run whose middle is nearest the paper's K, then to the earlier.
    """
    cuts = sorted(s for s in set(steps) if place.start < s <= place.end)
    if not cuts:
        return place
    bounds = [place.start, *cuts, place.end + 1]
    runs = [(a, b - 1) for a, b in zip(bounds[:-1], bounds[1:])]
    lit = sorted(set(lit or ()))
    dark = {r: not any(r[0] <= f <= r[1] for f in lit) for r in runs} if lit else dict.fromkeys(runs, False)
    a, b = min(runs, key=lambda r: (dark[r], -(r[1] - r[0]), abs((r[0] + r[1]) // 2 - place.k), r[0]))
    k = (a + b) // 2
    inside = [f for f in lit if a <= f <= b]
    if inside and k not in inside:  # the run's lit frame nearest its middle: the AQM needs light to judge
        k = min(inside, key=lambda f: (abs(f - k), f))
    return Placement(place.start, k, place.end, place.fmax)


def lit_keyframe(place: Placement, lit: Iterable[int]) -> Placement | None:
    """``place`` with K on the frame of ``lit`` nearest its K (the earlier of two), or None when
    none of its frames is lit (ours, not the paper's).

    Why: a segment whose pilot at K saw no indirect light (a lamp switched on later in it, a wall
    that appears) would be judged at a K the AQM sees nothing at, so any N_frame passes there; it
    took the cap instead (1,280,000 photons a frame, for a segment a lamp lights for a few frames).
    Judged at a frame its light reaches, the segment is decided as any other: Eq. (2) starts it
    and the AQM doubles N_frame until the halves agree there.
    """
    frames = [f for f in sorted(set(lit)) if place.start <= f <= place.end]
    if not frames:
        return None
    k = min(frames, key=lambda f: (abs(f - place.k), f))
    return Placement(place.start, k, place.end, place.fmax)


def frame_photons(n_frame: int, factor: float) -> int:
    """Photons a frame traces: N_frame times its factor (1, or ``end_photons`` next to an end)."""
    return int(math.ceil(n_frame * factor))
