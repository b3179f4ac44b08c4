"""The segments' pure decisions (pipeline/segments/decisions.py) on synthetic inputs with known answers:
Eq. (2), p_me with a lighting step at a known frame, the doubling loop, segment placement and the
photons of the frames next to an animation end or a lighting step."""
from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.collection.maps import WindowSpec, collection_windows
from pipeline.config import CollectionConfig, PhotonConfig, SegmentConfig
from pipeline.scene import read_scene
from pipeline.segments.decisions import (
    Placement,
    calibrated_start,
    doubling_loop,
    doublings_ahead,
    end_frames,
    energy_error,
    fmax_loop,
    grow_fmax,
    keyframe_off_steps,
    ladder_n_frame,
    lighting_steps,
    lit_keyframe,
    needed_n_frame,
    next_n_frame,
    p_me,
    photon_targets,
    pilot_n_frame,
    place_segment,
    unlit_n_frame,
    window_fmax_loop,
)


# --- Step 1: Eq. (2) --------------------------------------------------------------------------
def _moments(rng, p, n, weight=1.0):
    """Vertex moments of n photons landing on vertices with probabilities p (Poisson counts)."""
    hits = rng.poisson(n * p)
    return weight * hits, weight ** 2 * hits


def test_energy_error_falls_as_one_over_sqrt_n_and_the_pilot_finds_the_analytic_n(rng):
    # A static scene: vertex v receives a photon with probability p_v. With equal weights
    # E(N) = sum sqrt(N p_v) / sum N p_v = c / sqrt(N), c = sum sqrt(p) / sum p, so the N_frame for
    # which pooling F_max + 1 frames reaches E_max is (c / (E_max sqrt(F_max + 1)))^2.
    p = rng.gamma(2.0, 1.0, 1000)  # >= 13 hits a vertex on average: sqrt's Jensen bias stays ~1 %
    p /= p.sum() * 1.5  # a third of the photons escape or hit nothing
    c = np.sqrt(p).sum() / p.sum()
    e_max, fmax = 0.05, 30
    analytic = (c / (e_max * math.sqrt(fmax + 1))) ** 2
    for n_probe in (20_000, 80_000):
        e = energy_error(*_moments(rng, p, n_probe, weight=3.7))
        assert e == pytest.approx(c / math.sqrt(n_probe), rel=0.05)
        assert pilot_n_frame(n_probe, e, e_max, fmax) == pytest.approx(analytic, rel=0.20)
    # The photon weight cancels (E is scale-free) and no light means no estimate
    s, q = _moments(rng, p, 20_000)
    assert energy_error(s * 1e-30, q * 1e-60) == pytest.approx(energy_error(s, q), rel=1e-9)
    assert energy_error(np.zeros(5), np.zeros(5)) == math.inf


def test_pilot_on_a_real_static_scene_follows_eq2(tmp_path):
    # The STATIC built-in traced for real: E at N and at 4N differ by 2 (E ~ 1/sqrt(N)), so the
    # pilot's N_frame from either probe agrees within 20 %.
    from pipeline.collection.estimators import vertex_moments
    from pipeline.photons.tracing import PhotonRange, trace_batch
    from pipeline.scene import ElementMesh
    from pipeline.scene.builtin import write_builtin

    scene = read_scene(write_builtin("static", tmp_path / "static.glb"))
    elements = ElementMesh.build(scene)
    state = scene.pose_frame(1)
    errors = {}
    for n in (20_000, 80_000):
        b = trace_batch(state, elements, PhotonRange(1, 0, n), PhotonConfig(seed=5, photon_depth=8))
        from pipeline.store import DIRECT_BIT, ELEMENT_MASK
        indirect = (b.key & np.uint32(DIRECT_BIT)) == 0
        s, q = vertex_moments((b.key[indirect] & np.uint32(ELEMENT_MASK)).astype(np.int64), b.bary[indirect, 0],
                              b.bary[indirect, 1], b.energy[indirect], elements.element_vertices, elements.n_vertices)
        errors[n] = energy_error(s, q)
    assert errors[20_000] / errors[80_000] == pytest.approx(2.0, rel=0.10)
    n_a, n_b = (pilot_n_frame(n, e, 0.05, 15) for n, e in errors.items())
    assert n_a == pytest.approx(n_b, rel=0.20)


# --- Step 2: p_me ---------------------------------------------------------------------------------
def test_p_me_sees_a_lighting_step_at_a_known_frame(rng):
    # 41 frames, K = frame index 20, F_max = 20. Every element keeps its mean except half of them,
    # whose lighting doubles 5 frames after K (20 sigma at mu = 400): their forward windows break
    # there. Everything else keeps full windows but for Condition (1)'s false alarms (k = 2 over 10
    # frames: a few percent), the same both ways, so p_me forward is half of p_me backward.
    frames, elements, k = 41, 2000, 20
    mu = np.full(elements, 400.0)
    counts = rng.poisson(np.broadcast_to(mu, (frames, elements))).astype(np.uint32)
    step = np.arange(elements) < elements // 2
    counts[k + 5:, step] *= 2
    cfg = CollectionConfig(step_levels=0)  # Condition (1) alone: no element mesh for the regional step test
    back, fwd = collection_windows(counts, np.full(frames, 40_000.0), [k], WindowSpec("adaptive", 20), cfg)
    pb, pf = p_me(back[0], fwd[0], 20)
    assert pb > 0.9 and pf == pytest.approx(0.5 * pb, abs=0.03)
    assert np.all(fwd[0, step] <= 5)
    # Only the elements that count: the static half alone keeps (nearly) all its windows
    assert p_me(back[0], fwd[0], 20, considered=~step)[1] == pytest.approx(pb, abs=0.03)
    # A longer segment reaches the step backwards too when K moves past it
    assert grow_fmax(20, pb, pf, p_thr=0.4, step=15, cap=44) == 35
    assert grow_fmax(20, 0.39, 0.2, p_thr=0.4, step=15, cap=44) is None
    assert grow_fmax(44, 0.9, 0.9, p_thr=0.4, step=15, cap=44) is None
    assert grow_fmax(30, 0.9, 0.9, p_thr=0.4, step=15, cap=44) == 44


def test_a_segment_no_photon_lights_grows_and_keeps_its_rung():
    # No element hit in the segment: no indirect light to change, so F_max may grow; with F_max/2 = 0
    # no window reaches a neighbour
    back = fwd = np.zeros(50, np.uint8)
    assert p_me(back, fwd, 20, considered=np.zeros(50, bool)) == (1.0, 1.0)
    assert p_me(back, fwd, 1, considered=np.zeros(50, bool)) == (0.0, 0.0)
    assert p_me(back, fwd, 20, considered=np.arange(50) < 3) == (0.0, 0.0)
    assert grow_fmax(15, *p_me(back, fwd, 15, considered=np.zeros(50, bool)), p_thr=0.4, step=15, cap=44) == 30
    # a pilot that saw no indirect light: the segment keeps the smallest rung unless its frames are lit
    assert unlit_n_frame(1_250, 0, 1_280_000) == 1_250
    assert unlit_n_frame(1_250, 1, 1_280_000) == 1_280_000


def test_fmax_loop_grows_until_p_me_falls_below_p_thr():
    # p_me falls with F_max as the windows reach a change: 0.9 at 15, 0.5 at 30, 0.3 at 45 -> 44.
    seen = []

    def measure(place):
        seen.append(place)
        return {15: (0.9, 0.8), 30: (0.5, 0.35), 44: (0.3, 0.2)}[place.fmax]

    place, steps = fmax_loop(1, 15, 300, measure, p_thr=0.4, step=15, cap=44)
    assert [s["fmax"] for s in steps] == [15, 30, 44] and place.fmax == 44
    assert [p.k for p in seen] == [8, 16, 23]  # K moves F_max/2 from the previous segment's end
    place, steps = fmax_loop(1, 15, 300, lambda p: (0.39, 0.1), p_thr=0.4, step=15, cap=44)
    assert place.fmax == 15 and len(steps) == 1
    # A segment that already reaches the animation's end does not grow
    place, steps = fmax_loop(280, 15, 300, lambda p: (1.0, 1.0), p_thr=0.4, step=15, cap=44)
    assert len(steps) == 1 and place.end == 300


def test_window_fmax_is_the_shortest_rung_whose_halves_pass():
    seen = []

    def measure(fmax):
        seen.append(fmax)
        return {15: 4.4, 30: 2.3}[fmax]  # percent; d_thr 3 %

    assert window_fmax_loop(44, measure, d_thr=0.03, first=15, step=15) == (
        30, [{"fmax": 15, "d_aqm": 4.4}, {"fmax": 30, "d_aqm": 2.3}])
    assert seen == [15, 30]  # shortest first, and no rung tried once one passes
    # the first rung passing: no other tried
    assert window_fmax_loop(44, lambda f: 1.0, d_thr=0.03, first=15, step=15) == (15, [{"fmax": 15, "d_aqm": 1.0}])
    # none passing below F_max: F_max itself, not measured again (Step 3 judged it)
    fmax, tries = window_fmax_loop(44, lambda f: 9.0, d_thr=0.03, first=15, step=15)
    assert fmax == 44 and [t["fmax"] for t in tries] == [15, 30]
    # F_max at the ladder's first rung: nothing shorter to try
    assert window_fmax_loop(15, lambda f: 0.0, d_thr=0.03, first=15, step=15) == (15, [])


# --- Step 3: the doubling loop ----------------------------------------------------------------
def test_doubling_loop_stops_at_the_first_n_frame_below_d_thr():
    # d_AQM (percent) halves with every doubling: 12 % at 10,000 -> 3 % at 40,000 (<= d_thr = 3 %)
    measured = []

    def measure(n):
        measured.append(n)
        return 12.0 * 10_000 / n

    n, steps, capped = doubling_loop(10_000, measure, d_thr=0.03, n_max=640_000)
    assert n == 40_000 and measured == [10_000, 20_000, 40_000] and not capped
    assert [s["d_aqm"] for s in steps] == [12.0, 6.0, 3.0]
    n, steps, capped = doubling_loop(10_000, measure, d_thr=0.03, n_max=25_000)
    assert n == 25_000 and capped and measured[-1] == 25_000  # the cap is reached, then reported
    assert next_n_frame(10_000, 0.02, 0.03, 640_000) is None
    assert next_n_frame(10_000, 0.04, 0.03, 640_000) == 20_000
    assert next_n_frame(600_000, 0.04, 0.03, 640_000) == 640_000
    assert next_n_frame(640_000, 0.04, 0.03, 640_000) is None


def test_step_3_starts_on_a_rung_of_the_cap_and_lands_on_the_cap():
    # The rungs of 160,000 are 5,000, 10,000, ..., 80,000, 160,000; the nearest in log is taken
    assert ladder_n_frame(16_935, 1000, 160_000) == 20_000  # above sqrt(10,000 x 20,000) = 14,142
    assert ladder_n_frame(14_000, 1000, 160_000) == 10_000
    assert ladder_n_frame(78_071, 1000, 160_000) == 80_000 and ladder_n_frame(165_098, 1000, 160_000) == 160_000
    assert ladder_n_frame(math.inf, 1000, 640_000) == 640_000 and ladder_n_frame(12.2, 1000, 9000) == 1125
    assert ladder_n_frame(12.2, 5000, 160_000) == 5000 and ladder_n_frame(12.2, 5001, 160_000) == 10_000
    # ROOM's last segment started at 78,071 and went 156,142 -> 160,000, a sliver batch and an AQM
    # more; from its rung the doubling lands on the cap
    n, steps, capped = doubling_loop(ladder_n_frame(78_071, 1000, 160_000), lambda n: 30.0, d_thr=0.03,
                                     n_max=160_000)
    assert [s["n_frame"] for s in steps] == [80_000, 160_000] and capped


def test_doublings_ahead_extrapolates_the_fall_at_most_twice_as_steep():
    # ROOM's first segment: 52.5 -> 39.1 % over one doubling, d_thr 3 %. Falling at most 0.745^2
    # a doubling, d_AQM needs log(3 / 39.1) / log(0.555) = 4.36 doublings: 5 at least
    assert doublings_ahead((16_935, 0.525), (33_870, 0.391), 0.03) == 5
    assert doublings_ahead((10_000, 0.12), (20_000, 0.06), 0.03) == 1  # 0.5 left, at 1/4 a doubling
    assert doublings_ahead((10_000, 0.06), (20_000, 0.06), 0.03) == 1  # no fall: nothing to extrapolate
    assert doublings_ahead((10_000, 0.05), (20_000, 0.06), 0.03) == 1


def test_the_loop_doubles_once_a_step_whatever_the_fall():
    # d_AQM falling fast (50 -> 45 -> 1 %) is met one doubling at a time: the loop stops at the first
    # N_frame under d_thr, never past it
    fast = lambda n: 50.0 if n <= 5_000 else 45.0 if n <= 10_000 else 1.0  # noqa: E731
    n, steps, capped = doubling_loop(5_000, fast, d_thr=0.03, n_max=1_280_000)
    assert n == 20_000 and [s["n_frame"] for s in steps] == [5_000, 10_000, 20_000] and not capped


# --- placement and end frames -------------------------------------------------------------------
def test_segments_tile_the_animation_and_the_last_takes_in_a_stub():
    placed, start = [], 1
    while start <= 135:
        p = place_segment(start, 30, 135)
        placed.append((p.start, p.k, p.end))
        start = p.end + 1
    assert placed == [(1, 16, 31), (32, 47, 62), (63, 78, 93), (94, 109, 135)]  # 124-135 is a stub: merged
    p = place_segment(120, 30, 135)  # past the end: clipped, K in the middle of what is left
    assert (p.start, p.k, p.end) == (120, 127, 135)
    assert place_segment(1, 0, 10).frames == [1]


def test_frames_next_to_an_animation_end_get_more_photons():
    assert end_frames(1, 100, 10) == {1, 2, 3, 4, 5, 96, 97, 98, 99, 100}
    first = place_segment(1, 10, 100)
    targets = photon_targets(first, 40_000, first=1, last=100, end_factor=2.0)
    assert [targets[f] for f in first.frames] == [80_000] * 5 + [40_000] * 6
    middle = place_segment(40, 10, 100)
    assert set(photon_targets(middle, 40_000, first=1, last=100, end_factor=2.0).values()) == {40_000}


def test_an_end_factor_of_one_turns_the_end_photons_off():
    from pipeline.errors import ConfigError

    assert SegmentConfig(end_photons=1.0).end_photons == 1.0  # a closed lower bound: 1 is valid
    with pytest.raises(ConfigError, match="end_photons"):
        SegmentConfig(end_photons=0.999)
    with pytest.raises(ConfigError, match="k_sigma"):  # other float bounds stay open
        CollectionConfig(k_sigma=0.0)
    first = place_segment(1, 10, 100)
    assert set(photon_targets(first, 40_000, first=1, last=100, end_factor=1.0).values()) == {40_000}


def test_camera_flow_is_the_cameras_own_motion(tmp_path):
    # The AQM of Step 3 gets the pixel flow of camera motion (§6); a still camera gets none.
    from pipeline.frames.perceived import camera_flow
    from pipeline.scene.builtin import write_builtin

    orbit = read_scene(write_builtin("static", tmp_path / "static.glb"))  # the camera orbits the room
    flow = camera_flow(orbit, 10, 64, 48)
    assert flow.shape == (48, 64, 2) and np.isfinite(flow).all() and np.abs(flow).mean() > 0.1
    assert camera_flow(read_scene(write_builtin("room", tmp_path / "room.glb")), 10, 64, 48) is None


def test_the_next_segment_starts_where_the_last_ones_aqm_put_the_pilot():
    # Segment 0: the pilot said 10,000, the AQM loop ended at 320,000 (32x). Segment 1's pilot says
    # 12,000; the loop starts one doubling below the carried ratio, at 12,000 x 16 = 192,000 (the
    # rung 160,000 of the cap 640,000), and a segment whose AQM is content there stops there
    # instead of 5 doublings later.
    start = calibrated_start(12_000, (10_000, 320_000))
    assert start == 192_000
    need = 150_000  # this segment's d_AQM <= d_thr from here on

    def measure(n):
        return 2.0 if n >= need else 5.0

    n, steps, _ = doubling_loop(ladder_n_frame(start, 1000, 640_000), measure, d_thr=0.03, n_max=640_000)
    assert n == 160_000 and len(steps) == 1  # 192,000 on the cap's ladder
    n_paper, steps_paper, _ = doubling_loop(12_000, measure, d_thr=0.03, n_max=640_000)
    assert n_paper == 192_000 and len(steps_paper) == 5  # the paper's start: the same N_frame, 5 AQMs
    assert calibrated_start(12_000, None) == 12_000  # the first segment: Eq. 2 alone
    assert calibrated_start(12_000, (10_000, 15_000)) == 12_000  # a ratio under 2 changes nothing


def test_a_capped_segment_carries_over_what_it_still_lacked():
    # ROOM at a 160,000 cap: 80,000 -> 40 %, 160,000 -> 26 % against d_thr 3 %. Falling at most
    # twice as fast in log as over that doubling, d_AQM needs >= 3 doublings more: 1,280,000.
    steps = [{"n_frame": 80_000, "d_aqm": 40.0}, {"n_frame": 160_000, "d_aqm": 26.0}]
    need = needed_n_frame(160_000, steps, True, 0.03)
    assert need == 160_000 * 2 ** 3
    # The next segment, whose pilot says what the last one's did, starts at the cap: one AQM
    start = calibrated_start(20_000, (20_000, need))
    assert ladder_n_frame(start, 1000, 160_000) == 160_000
    # Carried over as it ended, it started a rung below and spent an AQM more to reach the cap
    assert ladder_n_frame(calibrated_start(20_000, (20_000, 160_000)), 1000, 160_000) == 80_000
    # A segment that met d_thr, or one stopped at the cap in its first step, as before / one doubling
    assert needed_n_frame(80_000, steps[:1], False, 0.03) == 80_000
    assert needed_n_frame(160_000, steps[1:], True, 0.03) == 320_000
    assert needed_n_frame(160_000, [], True, 0.03) == 160_000


# --- records on disk ------------------------------------------------------------------------------
def test_a_record_with_a_retired_field_loads_and_an_unknown_field_is_refused(tmp_path):
    # A record written while the F_max checks existed holds ``fmax_checks``: it still loads (and a
    # rerun finds its decision_hash stale), while a field no code ever wrote is a broken file.
    import json

    from pipeline.errors import LoomError
    from pipeline.segments.records import SegmentRecord, read_record, record_path, table, write_record

    rec = SegmentRecord(index=0, start=1, end=16, k=8, fmax=15, n_frame=20_000, temporal="adaptive", guided=True,
                        decision_hash="0" * 16, n_frame_steps=[{"n_frame": 20_000, "d_aqm": 2.0}])
    write_record(tmp_path, rec)
    path = record_path(tmp_path, 0)
    old = {**json.loads(path.read_text()), "fmax_checks": [{"n_frame": 20_000, "fmax_short": 15, "fmax_long": 30,
                                                             "ratio": 2.1, "limit": 1.64, "pays": False}]}
    path.write_text(json.dumps(old))
    loaded = read_record(tmp_path, 0)
    assert loaded == rec and "fmax_checks" not in loaded.to_dict()
    assert "20,000" in "\n".join(table([loaded]))
    path.write_text(json.dumps({**old, "no_such_field": 1}))
    with pytest.raises(LoomError, match="not a segment record"):
        read_record(tmp_path, 0)


def test_a_record_without_the_windows_fmax_collects_over_its_fmax(tmp_path):
    # A record decided before the windows' F_max existed has no window_fmax: resumed, its frames
    # are collected over the segment's F_max, as they were rendered; a record with one uses it.
    import json

    from pipeline.segments.records import SegmentRecord, read_record, record_path, table, write_record

    rec = SegmentRecord(index=0, start=1, end=45, k=23, fmax=44, n_frame=80_000, temporal="adaptive", guided=True,
                        decision_hash="0" * 16, window_fmax=30,
                        window_fmax_steps=[{"fmax": 15, "d_aqm": 4.4}, {"fmax": 30, "d_aqm": 2.3}])
    write_record(tmp_path, rec)
    assert read_record(tmp_path, 0).windows_fmax == 30
    assert "windows' F_max 30 (tried, d_AQM at K): 15: 4.40 %, 30: 2.30 %" in "\n".join(table([rec]))
    path = record_path(tmp_path, 0)
    old = {k: v for k, v in json.loads(path.read_text()).items() if not k.startswith("window_fmax")}
    path.write_text(json.dumps(old))
    loaded = read_record(tmp_path, 0)
    assert loaded.window_fmax is None and loaded.windows_fmax == 44 and loaded.window_fmax_steps == []


# --- lighting steps inside a segment --------------------------------------------------------------
def test_a_switched_light_is_found_at_its_frame_and_nowhere_else(rng):
    # 45 frames (a segment 46-90), F_max 44; 90 % of the elements' lighting drops to a third from
    # frame 68 on (a switched light), the rest stay. The regional step test over cells of 100
    # elements stops the switched elements' windows there; Condition (1)'s windows keep at least
    # min_extent frames, so at every other frame every element collects its previous frame.
    frames, elements = list(range(46, 91)), 3000
    counts = rng.poisson(np.full((len(frames), elements), 900.0)).astype(np.uint32)
    switched = np.arange(elements) < int(0.9 * elements)
    counts[68 - 46:, switched] = rng.poisson(300.0, (91 - 68, int(switched.sum())))
    cfg, cells, spec = CollectionConfig(), [np.arange(elements) // 100], WindowSpec("adaptive", 44)
    back, _ = collection_windows(counts, np.full(len(frames), 40_000.0), np.arange(len(frames)), spec, cfg,
                                 regions=cells)
    hit = np.ones(elements, bool)
    assert lighting_steps(back, hit, frames, p_thr=0.4) == [68]
    assert lighting_steps(back, hit, frames, p_thr=0.05) == []  # the tenth that stays collects across
    steady = rng.poisson(np.full((len(frames), elements), 900.0)).astype(np.uint32)
    back, _ = collection_windows(steady, np.full(len(frames), 40_000.0), np.arange(len(frames)), spec, cfg,
                                 regions=cells)
    assert lighting_steps(back, hit, frames, p_thr=0.4) == []
    assert lighting_steps(back, np.zeros(elements, bool), frames, p_thr=0.4) == []  # nothing lit: no step


def test_k_moves_to_the_middle_of_the_longest_steady_run():
    place = place_segment(46, 44, 135)
    assert place.k == 68
    assert keyframe_off_steps(place, []) == place
    assert keyframe_off_steps(place, [68]) == Placement(46, 79, 90, 44)  # 68-90 (23) beats 46-67 (22)
    assert keyframe_off_steps(place, [69]).k == 57  # 46-68 (23) beats 69-90 (22)
    assert keyframe_off_steps(place, [56, 80]).k == 67  # 56-79 is the longest: K in its middle
    assert keyframe_off_steps(place, [46, 91, 200]) == place  # its first frame and frames outside divide nothing
    # equal runs: the one whose middle is nearest the paper's K, then the earlier
    assert keyframe_off_steps(Placement(1, 5, 10, 10), [6]).k == 3


def test_frames_beside_a_lighting_step_get_the_end_photons():
    assert end_frames(1, 100, 10, steps=[50]) == {1, 2, 3, 4, 5, 45, 46, 47, 48, 49, 50, 51, 52, 53, 54,
                                                  96, 97, 98, 99, 100}
    middle = place_segment(40, 20, 100)  # frames 40-60
    targets = photon_targets(middle, 40_000, first=1, last=100, end_factor=2.0, steps=[50])
    assert [f for f in middle.frames if targets[f] == 80_000] == list(range(40, 60))
    assert targets[60] == 40_000
    assert set(photon_targets(middle, 40_000, first=1, last=100, end_factor=1.0, steps=[50]).values()) == {40_000}


def test_a_capped_segment_is_starred_and_the_table_says_what_to_try():
    from pipeline.segments.records import SegmentRecord, table

    done = SegmentRecord(index=0, start=1, end=45, k=23, fmax=44, n_frame=80_000, temporal="adaptive", guided=True,
                         decision_hash="0" * 16)
    capped = SegmentRecord(index=1, start=46, end=90, k=68, fmax=44, n_frame=1_280_000, temporal="adaptive",
                           guided=True, decision_hash="0" * 16, capped=True)
    assert not any(line.startswith("*") for line in table([done]))
    *rows, note = table([done, capped])
    assert "*" in rows[-1] and "*" not in rows[-2]
    assert note.startswith("* N_frame reached n_frame_max") and "loom bench elements" in note


def test_a_segment_is_judged_where_its_light_is():
    place = Placement(1, 16, 31, 30)
    assert lit_keyframe(place, []) is None and lit_keyframe(place, [40]) is None  # none of its frames lit
    assert lit_keyframe(place, range(25, 32)).k == 25  # a lamp switched on at 25: its nearest lit frame
    assert lit_keyframe(place, [10, 22]).k == 10  # equally near: the earlier
    # among the runs a lighting step leaves, the lit one, K on its lit frame nearest the run's middle
    assert keyframe_off_steps(place, [25], lit=range(25, 32)).k == 28
    assert keyframe_off_steps(place, [25]).k == 12  # without light to go by: the longest run, 1-24
    assert keyframe_off_steps(place, [25], lit=range(1, 32)).k == 12  # every frame lit: the longest run
    assert keyframe_off_steps(place, [25], lit=[3, 30]).k == 3  # both runs lit: the longest, at its lit frame
    assert keyframe_off_steps(place, [5, 25], lit=[20]).k == 20  # the lit frame of the chosen run
