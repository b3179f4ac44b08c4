"""The planner of the animation segments: Steps 1-3 of §5.2 for one segment at a time, on the pure
decisions of pipeline/segments/decisions.py (docs/07-segments.md §2).

For a segment it places the frames, runs the pilot at K (Step 1), grows F_max while p_me >= p_thr
(Step 2), doubles N_frame while d_AQM of the halves at K exceeds d_thr (Step 3, pipeline/segments/
halves.py), each doubling with the end frames' photons (§5.2) and off any lighting step it finds
(docs/07-segments.md §8), and writes the record (pipeline/segments/records.py). The pilot, the
windows, the maps and the halves are computed in the planner's own process; photon batches are
what it asks of its :class:`Executor`, which traces them into the store. It never touches Dask:
pipeline/run/coordinator.py is its Dask executor, which the make farm's decide step
(pipeline/run/farm.py) runs too.

Which photons a frame uses is fixed by the records: the fewest leading batches holding its
target (:func:`batches_in_use`, docs/07-segments.md §4), never what else the store holds.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, NamedTuple, Protocol

import numpy as np

from pipeline.collection.estimators import vertex_moments
from pipeline.collection.maps import (
    MapRequest,
    WindowSpec,
    collection_windows,
    illumination_maps,
    step_regions,
    window_counts,
)
from pipeline.frames.images import write_png
from pipeline.photons.tracing import PhotonRange, trace_batch

from .decisions import (
    Placement,
    calibrated_start,
    doubling_loop,
    energy_error,
    fmax_loop,
    keyframe_off_steps,
    ladder_n_frame,
    lighting_steps,
    lit_keyframe,
    needed_n_frame,
    p_me,
    photon_targets,
    pilot_n_frame,
    place_segment,
    unlit_n_frame,
    window_fmax_loop,
)
from .halves import HalvesJudge
from .job import Job
from .records import SegmentRecord, read_record, record_path, write_record

if TYPE_CHECKING:
    from pipeline.scene import ElementMesh, Scene
    from pipeline.store import PhotonStore


class Executor(Protocol):
    """What the planner asks of the code that runs it."""

    def shoot(self, targets: dict[int, int]) -> None:
        """Trace the :func:`next_batches` of ``targets`` ({frame: photons}, frames 1-based) into the
        store, so that every frame holds at least its target."""

    def progress(self, message: str) -> None:
        """Show one line of what the planner is deciding."""


@dataclass(frozen=True)
class NextBatch:
    """The batch a frame lacks: its photons ``photon_start`` .. ``photon_start + n_photons - 1``."""

    frame: int  # 1-based: the frame traced, the source of the frames sharing its photon set
    batch: int
    n_photons: int
    photon_start: int


class Judged(NamedTuple):
    """One doubling of Step 3: where K was, the lighting steps found, every frame's photons, Fig. 5 at K."""

    place: Placement
    steps: list[int]
    targets: dict[int, int]
    windows_at_k: dict


def next_batches(store: PhotonStore, targets: dict[int, int]) -> list[NextBatch]:
    """One batch more for every frame whose stored batches hold fewer photons than its target
    (N_frame doubles by one batch, nothing is traced again); frames sharing a photon set (camera-only
    motion) ask their source frame for the most any of them wants."""
    sources = store.source_frames()
    want: dict[int, int] = {}  # per source frame (1-based)
    for f, n in targets.items():
        src = int(sources[f - 1]) + 1
        want[src] = max(want.get(src, 0), int(n))
    prefix = store.prefixes_for({f - 1: n for f, n in want.items()})
    short = [f for f in sorted(want) if prefix[f - 1] is None]
    if not short:
        return []
    emitted, n_done = store.emitted(), store.batches_per_frame()
    return [NextBatch(f, int(n_done[f - 1]), want[f] - int(emitted[f - 1]), int(emitted[f - 1])) for f in short]


def batches_in_use(store: PhotonStore, targets: dict[int, int]) -> np.ndarray:
    """(n_frames,) leading batches in use per store frame for these targets (0 elsewhere)."""
    use = np.zeros(store.n_frames, np.int64)
    prefix = store.prefixes_for({f - 1: n for f, n in targets.items()})
    for f, n in targets.items():
        nb = prefix[f - 1]
        if nb is None:
            raise RuntimeError(f"frame {f} holds fewer than its {n} photons")
        use[f - 1] = nb
    return use


def known_targets(job: Job, index: int) -> dict[int, int]:
    """Targets of every decided segment before ``index`` (their photons are in the store)."""
    out: dict[int, int] = {}
    for i in range(index):
        rec = read_record(job.out_dir, i)
        if rec is not None:
            out.update(rec.targets())
    return out


def reach_targets(job: Job, rec: SegmentRecord) -> dict[int, int]:
    """Photon targets of every frame segment ``rec``'s windows may reach: the earlier segments',
    its own and the next one's (§5.2: a segment's photons are collected by its neighbours)."""
    if not rec.guided:
        return {f: job.n_photons for f in job.selection}
    out = {**known_targets(job, rec.index), **rec.targets()}
    after = read_record(job.out_dir, rec.index + 1)
    if after is not None and after.decision_hash == job.decision_hash:
        out.update(after.targets())
    return out


def window_histogram(back: np.ndarray, fwd: np.ndarray, fmax: int, counts: np.ndarray) -> dict:
    """Fig. 5: how many elements collect 0..F_max/2 frames back and forward at K, over the elements
    some photon of the segment hit (``counts``: (frames, E) records; never-hit ones say nothing)."""
    hit = counts.sum(axis=0) > 0
    half = max(int(fmax) // 2, int(back.max(initial=0)), int(fwd.max(initial=0)))
    return {"back": np.bincount(back[hit].astype(np.int64), minlength=half + 1).tolist(),
            "fwd": np.bincount(fwd[hit].astype(np.int64), minlength=half + 1).tolist(),
            "elements": int(hit.sum()), "fmax": int(fmax)}


class SegmentPlanner:
    """The segments of ``job`` decided one at a time: :meth:`record` gives a segment's current
    record, deciding it first when it has none. The seconds of the pilot and of the AQM are added
    to ``times`` (``shoot_s``, ``aqm_s``), where the executor adds its own."""

    def __init__(self, job: Job, store: PhotonStore, executor: Executor, times: dict[str, float]):
        self.job, self.store, self.executor, self.times = job, store, executor, times
        self.config = job.config

    # Loaded when first used: a fixed render's planner never needs them
    @cached_property
    def scene(self) -> Scene:
        return self.job.scene_ref.scene()

    @cached_property
    def elements(self) -> ElementMesh:
        return self.job.scene_ref.elements()

    @cached_property
    def judge(self) -> HalvesJudge:
        """Step 3's d_AQM of the halves, K's camera paths traced once for all its judgements."""
        return HalvesJudge(self.scene, self.elements, settings=self.job.settings, config=self.config)

    def record(self, index: int, start: int, fmax: int) -> SegmentRecord:
        """Segment ``index`` decided for this run: its record if current, else decided now."""
        rec = read_record(self.job.out_dir, index)
        if rec is not None and rec.decision_hash == self.job.decision_hash and rec.start == start:
            return rec
        return self.decide(index, start, fmax)

    def decide(self, index: int, start: int, fmax: int) -> SegmentRecord:
        """Steps 1-3 for the segment that begins at ``start`` with F_max ``fmax``; its photons
        traced and its record written."""
        job, cfg = self.job, self.config.segments
        t_start = time.perf_counter()
        if job.n_photons is not None:  # fixed settings: nothing to decide
            return self._fixed(index)
        prior = known_targets(job, index)
        if job.single_state:  # camera-only motion: one photon set, nothing to collect in time
            place = Placement(job.first, (job.first + job.last) // 2, job.last, 0)
        else:
            place = place_segment(start, fmax, job.last)

        # Step 1: pilot at K, N_frame from Eq. (2)
        pilot = self._pilot(index, place)
        unlit = pilot["n_pilot"] is None  # no indirect light in the pilot: Eq. (2) has no E
        start_n = cfg.n_frame_min if unlit else calibrated_start(pilot["n_pilot"], self._carried(index))
        pilot["n_start"] = None if unlit else start_n
        n = ladder_n_frame(start_n, cfg.n_frame_min, cfg.n_frame_max)
        t_init = time.perf_counter()

        # Step 2: F_max while p_me >= p_thr (never for camera-only motion: all frames share photons)
        lit_elements = [0]  # elements the photons of the segment's frames light, at its last F_max

        def p_me_of(at: Placement) -> tuple[float, float]:
            self.executor.shoot({f: n for f in at.frames})
            pb, pf, lit_elements[0] = self._p_me(index, at, {**prior, **{f: n for f in at.frames}})
            return pb, pf

        temporal = "off" if job.single_state else job.temporal
        if job.single_state:
            fmax_steps = []
        else:
            place, fmax_steps = fmax_loop(place.start, place.fmax, job.last, p_me_of, p_thr=cfg.p_thr,
                                          step=cfg.fmax_step, cap=cfg.fmax_cap)
        lit_frames = [] if job.single_state else self._lit_frames(place, {**prior, **{f: n for f in place.frames}})
        if unlit and lit_frames:  # judged where the light is (decisions.lit_keyframe), piloted there
            moved = lit_keyframe(place, lit_frames)
            again = self._pilot(index, moved)
            if again["n_pilot"] is not None:
                self.executor.progress(f"segment {index}: no indirect light at K {place.k}: K moves to frame "
                                       f"{moved.k}, the lit frame nearest it")
                place, pilot, unlit = moved, again, False
                pilot["n_start"] = calibrated_start(pilot["n_pilot"], self._carried(index))
                n = ladder_n_frame(pilot["n_start"], cfg.n_frame_min, cfg.n_frame_max)
        if unlit:
            n = unlit_n_frame(n, lit_elements[0], cfg.n_frame_max)
            pilot["no_indirect_light"] = lit_elements[0] == 0
            self.executor.progress(f"segment {index}: no indirect light at K {place.k}" + (
                f" nor in frames {place.start}-{place.end}: N_frame {n:,}, the AQM checks it" if n < cfg.n_frame_max
                else f", some in frames {place.start}-{place.end}: N_frame {n:,}, the cap"))
        t_fmax = time.perf_counter()

        # Step 3: N_frame doubled while d_AQM > d_thr. Each doubling first looks for lighting steps in
        # the photons it has (a step the noise hides at one N stands out at the next): K moves off
        # them, and the frames beside them are compensated as an animation's end frames are
        # (docs/07-segments.md §8); K is judged with the photons its frames will have, the end and
        # step frames' included. The record keeps the last doubling's steps, K and Fig. 5.
        segment = place
        judged: list[Judged] = []

        def d_aqm_of(n_frame: int) -> float:
            steps = [] if job.single_state else self._lighting_steps(index, segment, prior, n_frame)
            if steps and (not judged or judged[-1].steps != steps):
                self.executor.progress(f"segment {index}: lighting steps before frame(s) {', '.join(map(str, steps))}")
            at = keyframe_off_steps(segment, steps, lit_frames)
            targets = photon_targets(at, n_frame, first=job.first, last=job.last, end_factor=cfg.end_photons,
                                     steps=steps)
            self.executor.shoot(targets)
            d, at_k, _ = self._d_aqm(index, at, {**prior, **targets}, temporal)
            judged.append(Judged(at, steps, targets, at_k))
            beside = f" ({targets[at.k]:,} at K, beside an end or a step)" if targets[at.k] != n_frame else ""
            self.executor.progress(f"segment {index}: N_frame {n_frame:,}{beside} at K {at.k}: d_AQM {d:.2f} %")
            return d

        n, n_steps, capped = doubling_loop(n, d_aqm_of, d_thr=cfg.d_thr, n_max=cfg.n_frame_max)
        t_n = time.perf_counter()
        place, steps, final, windows_at_k = judged[-1]  # the loop ends at the N_frame it measured last

        # The windows' F_max: the shortest rung below F_max whose halves pass at this N_frame
        # (decisions.window_fmax_loop); a capped segment's halves pass at none.
        window_fmax, window_tries, tried = None, [], {}
        if temporal == "adaptive" and not capped and not job.single_state:
            def halves_at(fmax: int) -> float:
                tried[fmax] = self._d_aqm(index, place, {**prior, **final}, temporal, fmax=fmax)
                return tried[fmax][0]

            chosen, window_tries = window_fmax_loop(place.fmax, halves_at, d_thr=cfg.d_thr, first=cfg.fmax_initial,
                                                    step=cfg.fmax_step)
            if chosen != place.fmax:
                window_fmax, windows_at_k = chosen, tried[chosen][1]
                self._write_picture(index, tried[chosen][2])
                self.executor.progress(f"segment {index}: windows F_max {chosen} at K {place.k}: d_AQM "
                                       f"{tried[chosen][0]:.2f} %")
        ends = sorted(f for f, v in final.items() if v != n)
        rec = SegmentRecord(
            index=index, start=place.start, end=place.end, k=place.k, fmax=place.fmax, n_frame=n,
            temporal=temporal, guided=True, decision_hash=job.decision_hash, end_frames=ends, steps=steps,
            end_factor=cfg.end_photons, pilot=pilot, fmax_steps=fmax_steps, n_frame_steps=n_steps, capped=capped,
            windows_at_k=windows_at_k, window_fmax=window_fmax, window_fmax_steps=window_tries,
            times_s={"init_s": t_init - t_start, "fmax_s": t_fmax - t_init, "n_frame_s": t_n - t_fmax,
                     "decide_s": time.perf_counter() - t_start})
        write_record(job.out_dir, rec)
        return rec

    def _fixed(self, index: int) -> SegmentRecord:
        """--photons N --fmax F: one record over the render's frames, shot at N."""
        job = self.job
        t0 = time.perf_counter()
        self.executor.shoot({f: job.n_photons for f in job.selection})
        rec = SegmentRecord(index=index, start=job.first, end=job.last, k=(job.first + job.last) // 2,
                            fmax=job.fmax, n_frame=job.n_photons, temporal=job.temporal, guided=False,
                            decision_hash=job.decision_hash, times_s={"init_s": time.perf_counter() - t0})
        write_record(job.out_dir, rec)
        return rec

    def _add_time(self, key: str, since: float) -> None:
        self.times[key] = self.times.get(key, 0.0) + time.perf_counter() - since

    # --- Step 1 ------------------------------------------------------------------------------
    def _pilot(self, index: int, place: Placement) -> dict:
        """Step 1's probe, traced here in memory, never stored: its photons are the first
        ``pilot_photons`` of frame K's own stream (counter-based), so the frame's batches hold them
        anyway. Stored, it was one more batch at every K and one more wave of tasks a segment
        (docs/07-segments.md §2); read back from the store when K happened to be traced, E would
        depend on what else ran first."""
        cfg = self.config.segments
        n_probe = cfg.pilot_photons
        t0 = time.perf_counter()
        batch = trace_batch(self.scene.pose_frame(place.k), self.elements, PhotonRange(place.k, 0, n_probe),
                            self.config.photons)
        s, q = vertex_moments(*batch.indirect(), self.elements.element_vertices, self.elements.n_vertices)
        self._add_time("shoot_s", t0)
        e0 = energy_error(s, q)
        n_pilot = pilot_n_frame(n_probe, e0, cfg.e_max, place.fmax)
        self.executor.progress(f"segment {index}: pilot at K {place.k}: " + (
            f"E {e0:.3f} with {n_probe:,} photons -> N_frame {n_pilot:,.0f} (Eq. 2, F_max {place.fmax})"
            if math.isfinite(e0) else f"no indirect light in {n_probe:,} photons (Eq. 2 has no E)"))
        return {"frame": place.k, "n_probe": int(n_probe), "e_probe": e0 if math.isfinite(e0) else None,
                "e_target": cfg.e_max * float(np.sqrt(place.fmax + 1)),
                "n_pilot": n_pilot if np.isfinite(n_pilot) else None}

    def _carried(self, index: int) -> tuple[float, float] | None:
        """(pilot's N_frame, N_frame needed) of the segment before ``index``, for calibrated_start."""
        before = read_record(self.job.out_dir, index - 1) if index else None
        if before is None or not before.guided or not before.pilot.get("n_pilot"):
            return None
        return (before.pilot.get("n_pilot"),
                needed_n_frame(before.n_frame, before.n_frame_steps, before.capped, self.config.segments.d_thr))

    # --- Step 2 ------------------------------------------------------------------------------
    def _windows(self, place: Placement, targets: dict[int, int], frames: list[int]) -> tuple:
        """Condition (1)'s windows (back, fwd: (len(frames), E)) at ``frames`` over the photons of
        ``targets``, and the elements a photon of the segment hits (those that tell about the
        lighting, decisions.p_me)."""
        use = batches_in_use(self.store, targets)
        counts = window_counts(self.store, batches=use)
        emitted = np.array([self.store.photons_in(f, int(use[f])) for f in range(self.store.n_frames)], np.float64)
        # a regional step stops a walk as it stops the collection (pipeline/collection/regional_steps.py)
        back, fwd = collection_windows(counts, emitted, [f - 1 for f in frames], WindowSpec("adaptive", place.fmax),
                                       self.config.collection,
                                       regions=step_regions(self.elements, self.config.collection))
        return back, fwd, counts[place.start - 1:place.end].sum(axis=0) > 0

    def _lit_frames(self, place: Placement, targets: dict[int, int]) -> list[int]:
        """Frames of ``place`` whose photons (those of ``targets``) record indirect light."""
        counts = window_counts(self.store, batches=batches_in_use(self.store, targets))[place.start - 1:place.end]
        return [place.start + i for i in np.flatnonzero(counts.sum(axis=1) > 0).tolist()]

    def _p_me(self, index: int, place: Placement, targets: dict[int, int]) -> tuple[float, float, int]:
        """(p_me back, p_me forward, elements any photon of the segment lights) at K."""
        back, fwd, hit = self._windows(place, targets, [place.k])
        pb, pf = p_me(back[0], fwd[0], place.fmax, hit)
        self.executor.progress(f"segment {index}: F_max {place.fmax}, K {place.k}: p_me {pb:.2f} back, "
                               f"{pf:.2f} forward")
        return pb, pf, int(np.count_nonzero(hit))

    def _lighting_steps(self, index: int, place: Placement, prior: dict[int, int], n_frame: int) -> list[int]:
        """Frames of the segment that begin after an abrupt lighting change (decisions.lighting_steps)
        in its photons at ``n_frame`` (the end frames' included), from the frame before it, which an
        earlier segment traced: a step at its first frame counts."""
        job = self.job
        targets = photon_targets(place, n_frame, first=job.first, last=job.last,
                                 end_factor=self.config.segments.end_photons)
        self.executor.shoot(targets)
        frames = list(range(max(place.start - 1, job.first), place.end + 1))
        back, _, hit = self._windows(place, {**prior, **targets}, frames)
        return lighting_steps(back, hit, frames, self.config.segments.p_thr)

    # --- Step 3 ------------------------------------------------------------------------------
    def _d_aqm(self, index: int, place: Placement, targets: dict[int, int], temporal: str,
               fmax: int | None = None) -> tuple[float, dict, np.ndarray]:
        """d_AQM (percent) of I1(K) against I2(K) as the viewer sees them with windows of F_max
        ``fmax`` (None: the placement's), Fig. 5's windows at K and the M_AQM picture; the picture
        is written beside the segment record unless ``fmax`` is given (a try of the windows' F_max)."""
        t0 = time.perf_counter()
        use = batches_in_use(self.store, targets)
        k = place.k
        windows_fmax = place.fmax if fmax is None else fmax
        # Each half is reconstructed as the final frame will be, spatial filter included (Step 5):
        # on ATRIUM's 43,000 small elements (the paper's mesh) the filter, not N_frame, removes most of what the
        # unfiltered halves differ by; judged unfiltered, the loop would trace for noise no frame shows.
        (lit,) = illumination_maps(self.store, self.elements, self.scene,
                                   MapRequest(WindowSpec(temporal, windows_fmax), [k - 1], batches=use, halves=True),
                                   self.config.collection, self.config.filter)
        judged = self.judge.difference(lit.irradiance, k)
        counts = window_counts(self.store, batches=use)[place.start - 1:place.end]
        at_k = window_histogram(lit.back, lit.fwd, windows_fmax, counts)
        if fmax is None:
            self._write_picture(index, judged.picture)
        self._add_time("aqm_s", t0)
        return judged.d_aqm, at_k, judged.picture

    def _write_picture(self, index: int, picture: np.ndarray) -> None:
        path = record_path(self.job.out_dir, index).with_suffix(".aqm.png")
        path.parent.mkdir(parents=True, exist_ok=True)
        write_png(path, picture)
