"""The segment planner (pipeline/segments/planner.py) without Dask: its executor here traces the
batches the planner asks for in this process (workers/shoot.py's task: real kernels, a real store),
and what the planner decides and records is checked against the pure decisions and the store."""
from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from pipeline.benchmarks.error import write_scene
from pipeline.collection.estimators import vertex_moments
from pipeline.collection.maps import MapRequest, WindowSpec, illumination_maps
from pipeline.config import RenderConfig
from pipeline.frames.settings import RenderSettings
from pipeline.photons.tracing import PhotonRange, trace_batch
from pipeline.run.shoot import open_store, plan
from pipeline.scene import read_scene
from pipeline.scene.builtin import write_builtin
from pipeline.scene.builtin.gltf_builder import GltfBuilder
from pipeline.scene.builtin.shapes import quad
from pipeline.scene.scene_cache import load_elements
from pipeline.segments.decisions import (
    Placement,
    calibrated_start,
    energy_error,
    grow_fmax,
    keyframe_off_steps,
    ladder_n_frame,
    needed_n_frame,
    next_n_frame,
    pilot_n_frame,
    place_segment,
)
from pipeline.segments.halves import HalvesJudge
from pipeline.segments.job import Job
from pipeline.segments.planner import (
    NextBatch,
    SegmentPlanner,
    batches_in_use,
    known_targets,
    next_batches,
    reach_targets,
    window_histogram,
)
from pipeline.segments.records import SegmentRecord, read_record, record_path, write_record
from workers.shoot import ShootRequest, shoot_task

# Every step runs on ROOM's frames 60-80 at 48x36: F_max grows 6 -> 10, and N_frame doubles from the
# rung 2,000 of the cap (the pilot asks about 1,900) to the cap, 8,000, where d_AQM (85, 86, 80 %) falls under 80 %
CHEAP = RenderConfig.from_dict({"pilot_photons": 2000, "e_max": 0.2, "n_frame_min": 1000, "n_frame_max": 8000,
                                "d_thr": 0.8, "fmax_initial": 6, "fmax_step": 4, "fmax_cap": 10})


class InProcess:
    """The planner's Executor in this process: each batch :func:`next_batches` names, traced by the
    photon task itself; progress lines kept."""

    def __init__(self, job: Job, store):
        self.job, self.store = job, store
        self.traced: list[NextBatch] = []
        self.lines: list[str] = []

    def shoot(self, targets: dict[int, int]) -> None:
        job, cfg = self.job, self.job.config.photons
        for b in next_batches(self.store, targets):
            shoot_task(ShootRequest(job.scene_ref, job.store_url, b.batch,
                                    PhotonRange(b.frame, b.photon_start, b.n_photons), cfg))
            self.traced.append(b)

    def progress(self, message: str) -> None:
        self.lines.append(message)


def _job(tmp_path, name: str, frames: str, config: RenderConfig = CHEAP, path=None, **kw):
    """A Job over ``frames`` of the built-in scene ``name`` (or the glTF file ``path``) and its fresh store."""
    scene = read_scene(path or write_builtin(name, tmp_path / f"{name}.glb"))
    p = plan(scene, frames, 1, config.photons)
    url = str(tmp_path / "photons.zarr")
    store = open_store(p, url, keep_records=False)
    job = Job(scene_path=str(scene.path), scene_hash=scene.scene_hash, camera=None, camera_name=scene.camera_name,
              element_size=config.photons.element_size, store_url=url, out_dir=str(tmp_path / "out"), first=p.frames[0],
              last=p.frames[-1], selection=tuple(p.frames), settings=RenderSettings(width=48, height=36, spp=1),
              config=config, render_hash="look", decision_hash="decided", fmax=config.segments.fmax_initial,
              n_photons=None, temporal="adaptive", single_state=False)
    return replace(job, **kw), store


@pytest.fixture(scope="module")
def decided(tmp_path_factory):
    """ROOM's first segment of frames 60-80 as the planner decides it."""
    job, store = _job(tmp_path_factory.mktemp("planner"), "room", "60-80")
    executor = InProcess(job, store)
    times: dict[str, float] = {}
    rec = SegmentPlanner(job, store, executor, times).decide(0, job.first, job.fmax)
    return job, store, executor, times, rec


def test_the_pilot_is_eq2_of_its_own_probe_at_k(decided):
    job, _, executor, times, rec = decided
    cfg = job.config.segments
    elements = load_elements(job.scene_path, job.scene_hash, job.element_size)
    scene = read_scene(job.scene_path)
    first = place_segment(job.first, job.fmax, job.last)
    batch = trace_batch(scene.pose_frame(first.k), elements, PhotonRange(first.k, 0, cfg.pilot_photons),
                        job.config.photons)
    e = energy_error(*vertex_moments(*batch.indirect(), elements.element_vertices, elements.n_vertices))
    assert rec.pilot["frame"] == first.k and rec.pilot["e_probe"] == e
    assert rec.pilot["n_pilot"] == pilot_n_frame(cfg.pilot_photons, e, cfg.e_max, job.fmax)
    assert rec.pilot["n_start"] == rec.pilot["n_pilot"]  # the first segment: Eq. (2) alone
    assert times["shoot_s"] > 0 and times["aqm_s"] > 0  # the pilot's and the AQM's seconds, for the record


def test_the_loops_follow_the_decisions(decided):
    job, _, executor, _, rec = decided
    cfg = job.config.segments
    fmax = [s["fmax"] for s in rec.fmax_steps]
    assert fmax[:2] == [6, 10]  # p_me >= p_thr on ROOM's walls
    for s, after in zip(rec.fmax_steps, fmax[1:] + [None]):
        assert s["k"] == place_segment(job.first, s["fmax"], job.last).k
        grown = grow_fmax(s["fmax"], s["p_me_back"], s["p_me_fwd"], p_thr=cfg.p_thr, step=cfg.fmax_step,
                          cap=cfg.fmax_cap)
        assert after == grown or (after is None and place_segment(job.first, s["fmax"], job.last).end == job.last)
    assert Placement(rec.start, rec.k, rec.end, rec.fmax) == place_segment(job.first, fmax[-1], job.last)
    n = [s["n_frame"] for s in rec.n_frame_steps]
    d = [s["d_aqm"] for s in rec.n_frame_steps]
    assert n[0] == ladder_n_frame(rec.pilot["n_start"], cfg.n_frame_min, cfg.n_frame_max)
    assert n[1:] == [next_n_frame(n[i], d[i] / 100, cfg.d_thr, cfg.n_frame_max) for i in range(len(n) - 1)]
    assert n == [2000, 4000, 8000] and rec.n_frame == 8000 and not rec.capped
    # the windows' F_max: the shortest rung below F_max whose halves pass at the final N_frame
    tries = rec.window_fmax_steps
    assert [t["fmax"] for t in tries] == list(range(cfg.fmax_initial, rec.fmax, cfg.fmax_step))[:len(tries)]
    assert all(t["d_aqm"] / 100 > cfg.d_thr for t in tries[:-1])
    if rec.window_fmax is not None:
        assert rec.window_fmax == tries[-1]["fmax"] < rec.fmax and tries[-1]["d_aqm"] / 100 <= cfg.d_thr
    else:
        assert rec.windows_fmax == rec.fmax and all(t["d_aqm"] / 100 > cfg.d_thr for t in tries)
    # one progress line a decision: the pilot, each p_me, each d_AQM, shorter windows when chosen
    assert len(executor.lines) == (1 + len(rec.fmax_steps) + len(rec.n_frame_steps)
                                   + (rec.window_fmax is not None))
    assert executor.lines[0].startswith(f"segment 0: pilot at K {rec.fmax_steps[0]['k']}")


def test_the_store_holds_exactly_the_records_targets(decided):
    # Each batch added what its frame lacked of the target asked (one batch a doubling), so what a
    # frame emitted is its final target: N_frame, or end_photons x N_frame next to an animation end
    job, store, executor, _, rec = decided
    targets = rec.targets()
    assert rec.end_frames and all(targets[f] == 2 * rec.n_frame for f in rec.end_frames)
    emitted = store.emitted()
    assert {f: int(emitted[f - 1]) for f in range(rec.start, rec.end + 1)} == targets
    assert not emitted[:rec.start - 1].any()
    assert next_batches(store, targets) == []
    assert record_path(job.out_dir, 0).with_suffix(".aqm.png").stat().st_size > 0
    windows = rec.windows_at_k
    assert sum(windows["back"]) == sum(windows["fwd"]) == windows["elements"] > 0
    assert read_record(job.out_dir, 0) == rec


def test_judgements_relighting_ks_paths_have_the_bits_of_fresh_renders(decided):
    # The planner traced K's camera paths at its first judgement and relit them for the rest
    # (pipeline/segments/halves.py); a judge that traces them anew for each gives the recorded d_AQM
    job, store, _, _, rec = decided
    scene = read_scene(job.scene_path)
    elements = load_elements(job.scene_path, job.scene_hash, job.element_size)
    use = batches_in_use(store, rec.targets())
    judged = [(rec.fmax, rec.n_frame_steps[-1]["d_aqm"])] + [(t["fmax"], t["d_aqm"]) for t in rec.window_fmax_steps]
    assert len(judged) >= 2
    relit = HalvesJudge(scene, elements, settings=job.settings, config=job.config)
    for fmax, recorded in judged:
        (lit,) = illumination_maps(store, elements, scene, MapRequest(WindowSpec("adaptive", fmax), [rec.k - 1],
                                                                      batches=use, halves=True),
                                   job.config.collection, job.config.filter)
        fresh = HalvesJudge(scene, elements, settings=job.settings, config=job.config).difference(lit.irradiance, rec.k)
        again = relit.difference(lit.irradiance, rec.k)
        assert fresh.d_aqm == again.d_aqm == recorded and np.array_equal(fresh.picture, again.picture)
    assert relit.traced_frames == 1
    # paths larger than the judge may keep are traced for every judgement, to the same d_AQM
    small = HalvesJudge(scene, elements, settings=job.settings, config=job.config, kept_bytes=1000)
    assert [small.difference(lit.irradiance, rec.k).d_aqm for _ in range(2)] == [recorded] * 2
    assert small.traced_frames == 2


def test_a_current_record_is_kept_and_a_stale_one_decided_again(decided):
    job, store, executor, _, rec = decided
    traced, lines = len(executor.traced), len(executor.lines)
    assert SegmentPlanner(job, store, executor, {}).record(0, job.first, job.fmax) == rec
    assert (len(executor.traced), len(executor.lines)) == (traced, lines)  # nothing traced, nothing measured
    # A looser d_thr decides again on the stored photons: the first N_frame passes, no batch is traced
    lenient = replace(job, config=RenderConfig.from_dict({**CHEAP.to_dict(), "d_thr": 0.95}),
                      decision_hash="lenient", out_dir=job.out_dir + "-lenient")
    again = SegmentPlanner(lenient, store, executor, {}).record(0, job.first, job.fmax)
    assert again.decision_hash == "lenient" and len(again.n_frame_steps) == 1
    assert again.n_frame == rec.n_frame_steps[0]["n_frame"] and len(executor.traced) == traced


def test_the_next_segment_starts_after_this_one_on_its_photons_and_its_calibration(decided):
    job, store, executor, _, rec = decided
    nxt = SegmentPlanner(job, store, executor, {}).record(1, rec.end + 1, rec.fmax)
    assert (nxt.start, nxt.end, nxt.fmax_steps[0]["fmax"]) == (rec.end + 1, job.last, rec.fmax)
    needed = needed_n_frame(rec.n_frame, rec.n_frame_steps, rec.capped, job.config.segments.d_thr)
    carried = (rec.pilot["n_pilot"], needed)
    assert nxt.pilot["n_start"] == calibrated_start(nxt.pilot["n_pilot"], carried)
    # segment 0's photons stay as they were, and each segment traced its own frames only
    emitted = store.emitted()
    assert {f: int(emitted[f - 1]) for f in range(job.first, job.last + 1)} == {**rec.targets(), **nxt.targets()}
    assert not emitted[:job.first - 1].any() and not emitted[job.last:].any()
    assert reach_targets(job, rec) == {**rec.targets(), **nxt.targets()}


def test_fixed_settings_trace_n_at_every_frame_and_decide_nothing(tmp_path):
    job, store = _job(tmp_path, "room", "3-6", n_photons=1500, fmax=4)
    executor = InProcess(job, store)
    rec = SegmentPlanner(job, store, executor, {}).decide(0, job.first, job.fmax)
    assert (rec.start, rec.end, rec.k, rec.fmax, rec.n_frame, rec.guided) == (3, 6, 4, 4, 1500, False)
    assert not rec.pilot and not rec.fmax_steps and not rec.n_frame_steps and not executor.lines
    assert [(b.frame, b.batch, b.n_photons, b.photon_start) for b in executor.traced] == \
        [(f, 0, 1500, 0) for f in range(3, 7)]
    assert reach_targets(job, rec) == {f: 1500 for f in range(3, 7)}


def test_frames_sharing_a_photon_set_ask_their_source_for_the_most_any_wants(tmp_path):
    # STATIC's frames all share frame 1's photons (camera-only motion): one batch of the largest
    # target, then one batch more of what a larger target lacks
    job, store = _job(tmp_path, "static", "1-30", single_state=True)
    executor = InProcess(job, store)
    assert next_batches(store, {1: 100, 5: 300, 30: 200}) == [NextBatch(1, 0, 300, 0)]
    executor.shoot({1: 100, 5: 300, 30: 200})
    assert next_batches(store, {f: 300 for f in range(1, 31)}) == []
    assert next_batches(store, {3: 500}) == [NextBatch(1, 1, 200, 300)]


def test_reach_targets_are_the_earlier_own_and_current_next_segments(tmp_path):
    job, _ = _job(tmp_path, "room", "1-40")

    def rec(index, start, end, n, decision_hash="decided"):
        return SegmentRecord(index=index, start=start, end=end, k=(start + end) // 2, fmax=end - start,
                             n_frame=n, temporal="adaptive", guided=True, decision_hash=decision_hash,
                             end_frames=[1] if start == 1 else [], end_factor=2.0)

    for r in (rec(0, 1, 10, 100), rec(1, 11, 20, 200), rec(2, 21, 30, 300, "stale")):
        write_record(job.out_dir, r)
    assert known_targets(job, 2) == {1: 200, **{f: 100 for f in range(2, 11)}, **{f: 200 for f in range(11, 21)}}
    # the next segment's photons count only when its record is current
    assert reach_targets(job, read_record(job.out_dir, 1)) == known_targets(job, 2)
    write_record(job.out_dir, rec(2, 21, 30, 300))
    assert reach_targets(job, read_record(job.out_dir, 1)) == {**known_targets(job, 2),
                                                               **{f: 300 for f in range(21, 31)}}


def test_window_histogram_counts_the_elements_the_segment_hit():
    back = np.array([0, 3, 3, 1, 2], np.uint8)
    fwd = np.array([2, 2, 0, 1, 3], np.uint8)
    counts = np.array([[1, 0, 2, 0, 0], [0, 1, 0, 3, 0]])  # element 4 never hit: it says nothing
    h = window_histogram(back, fwd, 6, counts)
    assert h == {"back": [1, 1, 0, 2], "fwd": [1, 1, 2, 0], "elements": 4, "fmax": 6}


def test_a_switched_light_moves_k_and_gives_the_frames_beside_it_the_end_photons(tmp_path):
    # ROOM's light jumps at frame 66, inside the segment 60-70 whose K is 65. Up to 8,000 photons a
    # frame the step hides in the noise and K stays; at 16,000 the regional step test sees it, K moves
    # to the middle of 60-65 and every frame within F_max/2 of the step or of an end traces
    # end_photons x N_frame (docs/07-segments.md §8)
    path = write_scene("room", tmp_path / "jump.glb", 66)
    config = RenderConfig.from_dict({**CHEAP.to_dict(), "n_frame_max": 16_000, "d_thr": 0.01})
    job, store = _job(tmp_path, "room", "60-80", config=config, path=path)
    executor = InProcess(job, store)
    rec = SegmentPlanner(job, store, executor, {}).decide(0, job.first, job.fmax)
    assert (rec.start, rec.end, rec.fmax) == (60, 70, 10) and rec.steps == [66]
    assert rec.k == 62 == keyframe_off_steps(place_segment(60, 10, 80), [66]).k
    assert [s["n_frame"] for s in rec.n_frame_steps] == [2_000, 4_000, 8_000, 16_000] and rec.capped
    assert rec.end_frames == list(range(60, 71)) and set(rec.targets().values()) == {32_000}
    judged = [line for line in executor.lines if "d_AQM" in line]
    assert all(" at K 65:" in line for line in judged[:3])
    assert executor.lines[-2] == "segment 0: lighting steps before frame(s) 66"
    assert judged[-1].startswith("segment 0: N_frame 16,000 (32,000 at K, beside an end or a step) at K 62")
    # the store holds what the record says: nothing traced beyond the targets
    assert store.emitted()[59:70].tolist() == [32_000] * 11


def _sunlit_plane(path, wall_from: int | None = None):
    """A 1 m grey plane sliding along x for 20 frames under a point light 1 m above it: a flat
    surface alone has no indirect light. With ``wall_from``, a wall facing it at its +x edge, scaled
    to nothing until that frame (a zero scale is never hit), then whole: the two interreflect."""
    b = GltfBuilder()
    grey = b.add_material("grey", (0.7, 0.7, 0.7))
    plane = b.add_node("plane", b.add_mesh("plane", *quad((-0.5, 0, -0.5), (0, 0, 1), (1, 0, 0)), material=grey))
    end = 19 / 30
    b.add_animation("slide", plane, "translation", [0.0, end], [[0, 0, 0], [0.3, 0, 0]])
    b.add_node("lamp", translation=(0.0, 1.0, 0.0), light=b.add_point_light("lamp", (1, 1, 1), 5.0))
    if wall_from is not None:
        wall = b.add_node("wall", b.add_mesh("wall", *quad((1.0, 0, -0.5), (0, 1, 0), (0, 0, 1)), material=grey),
                          scale=(0.0, 0.0, 0.0))
        b.add_animation("appear", wall, "scale", [0.0, (wall_from - 1.5) / 30], [[0, 0, 0], [1, 1, 1]],
                        interpolation="STEP")
    return b.write(path)


def test_a_segment_without_indirect_light_stays_on_the_smallest_rung(tmp_path):
    # The pilot at K records no indirect light (Eq. 2 has no E), nor do the segment's frames: p_me
    # is (1, 1), F_max grows to the cap, and N_frame is the smallest rung, not the cap
    job, store = _job(tmp_path, "plane", "1-20", path=_sunlit_plane(tmp_path / "plane.glb"))
    executor = InProcess(job, store)
    rec = SegmentPlanner(job, store, executor, {}).decide(0, job.first, job.fmax)
    assert rec.pilot["n_pilot"] is None and rec.pilot["n_start"] is None and rec.pilot["e_probe"] is None
    assert rec.e_pilot_text == "none" and rec.without_indirect_light  # the record is strict JSON: no Infinity
    json.loads(record_path(job.out_dir, 0).read_text(), parse_constant=lambda c: pytest.fail(f"{c} in the record"))
    assert executor.lines[0] == "segment 0: pilot at K 4: no indirect light in 2,000 photons (Eq. 2 has no E)"
    assert [s["fmax"] for s in rec.fmax_steps] == [6, 10] and rec.fmax_steps[0]["p_me_back"] == 1.0
    assert rec.n_frame == 1_000 == ladder_n_frame(1_000, 1_000, 8_000) and not rec.capped
    assert [s["n_frame"] for s in rec.n_frame_steps] == [1_000] and rec.n_frame_steps[0]["d_aqm"] == 0.0
    assert "segment 0: no indirect light at K 6 nor in frames 1-11: N_frame 1,000, the AQM checks it" in executor.lines
    assert store.emitted()[:11].max() <= 2_000  # the end frames' double at most


def test_light_away_from_an_unlit_k_moves_k_there(tmp_path):
    # The wall appears at frame 9, after K 6 (F_max 10): the pilot at K sees no indirect light, the
    # segment's frames do. K moves to frame 9, the lit frame nearest it, the pilot there gives Eq.
    # (2)'s start and the AQM judges there: 2,000 photons a frame where the cap was 8,000
    path = _sunlit_plane(tmp_path / "wall.glb", wall_from=9)
    job, store = _job(tmp_path, "wall", "1-20", path=path)
    executor = InProcess(job, store)
    rec = SegmentPlanner(job, store, executor, {}).decide(0, job.first, job.fmax)
    assert executor.lines[0] == "segment 0: pilot at K 4: no indirect light in 2,000 photons (Eq. 2 has no E)"
    assert "segment 0: no indirect light at K 6: K moves to frame 9, the lit frame nearest it" in executor.lines
    assert rec.pilot["frame"] == 9 and rec.pilot["n_pilot"] > 0 and (rec.start, rec.end) == (1, 11)
    assert rec.k >= 9  # judged where the wall is (off the lighting step at 9, on the lit side)
    assert rec.n_frame == 2_000 < 8_000 and not rec.capped and not rec.without_indirect_light
    assert rec.n_frame_steps[-1]["d_aqm"] > 0  # the halves differ where the light is: the AQM saw it
