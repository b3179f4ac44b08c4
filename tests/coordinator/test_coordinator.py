"""The segment coordinator end to end on real parts (Embree, PoCL, zarr on disk, Dask processes on
127.0.0.1): the same records and frames synchronously and on a 2-worker cluster, after a kill and
rerun, and after reprocessing one segment; camera-only motion traces one photon set."""
from __future__ import annotations

import json
import re
import shutil
import signal
import subprocess
import sys
import time

import pytest

from pipeline.frames.images import frame_paths
from pipeline.segments.decisions import next_n_frame
from pipeline.segments.records import read_record, read_records

# Small and quick, but every step runs: F_max grows 6 -> 10, N_frame doubles, two segments.
CHEAP = {"pilot_photons": 2000, "n_frame_min": 1000, "n_frame_max": 16000, "d_thr": 0.45,
         "fmax_initial": 6, "fmax_step": 4, "fmax_cap": 10}
FRAMES = "60-80"


def _loom(*args, check=True):
    result = subprocess.run([sys.executable, "-m", "pipeline", *map(str, args)], capture_output=True, text=True)
    if check:
        assert result.returncode == 0, result.stderr
    return result


def _render_args(scene, out, config, *extra):
    return ["render", scene, "--frames", FRAMES, "--out", out, "--resolution", "48x36", "--spp", "1",
            "--config", config, "--quiet", *extra]


def _records(out):
    return [r.without_times() for r in read_records(out)]


def _frames(out):
    first, last = map(int, FRAMES.split("-"))
    return {f: tuple(p.read_bytes() for p in frame_paths(out, f)) for f in range(first, last + 1)}


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("coord")
    scene = tmp / "room.glb"
    _loom("scene", "room", "-o", scene)
    config = tmp / "cheap.json"
    config.write_text(json.dumps(CHEAP))
    return tmp, scene, config


@pytest.fixture(scope="module")
def reference(room):
    tmp, scene, config = room
    out = tmp / "sync"
    _loom(*_render_args(scene, out, config, "--scheduler", "synchronous"))
    return out


def test_every_step_runs_and_is_recorded(reference):
    recs = read_records(reference)
    assert len(recs) >= 2 and recs[0].start == 60 and recs[-1].end == 80
    assert all(r.status == "done" and r.guided for r in recs)
    for a, b in zip(recs, recs[1:]):
        assert b.start == a.end + 1 and b.fmax_steps[0]["fmax"] == a.fmax  # segment order, F_max handed on
    first = recs[0]
    assert [s["fmax"] for s in first.fmax_steps][:2] == [6, 10]  # p_me >= p_thr on ROOM's walls
    assert first.pilot["n_probe"] == 2000 and first.pilot["e_probe"] > 0
    for r in recs:
        d = [s["d_aqm"] for s in r.n_frame_steps]
        # stops at the first N_frame with d_AQM <= d_thr, or at the cap with that reported
        assert all(x > 45 for x in d[:-1])
        assert (d[-1] <= 45) != r.capped
        # from a rung of the cap, the next N_frame is what segments.next_n_frame says of the steps so far
        n, cap, d_thr = [s["n_frame"] for s in r.n_frame_steps], CHEAP["n_frame_max"], CHEAP["d_thr"]
        assert n[0] in {-(-cap // 2 ** k) for k in range(16)}
        assert n[1:] == [next_n_frame(n[i], d[i] / 100, d_thr, cap) for i in range(len(n) - 1)]
        assert set(r.frames) == {str(f) for f in range(r.start, r.end + 1)}
        assert all(v["adaptation"] > 0 for v in r.frames.values())
        # the F_max Step 2 ended on; a segment spans F_max + 1 frames unless the range ends first
        assert r.fmax == r.fmax_steps[-1]["fmax"]
        assert r.end - r.start >= min(r.fmax, int(FRAMES.split("-")[1]) - r.start)
    assert recs[0].end_frames[0] == 60 and recs[-1].end_frames[-1] == 80  # end compensation
    table = _loom("segments", reference).stdout
    assert "N_frame" in table and "F_max" in table and f"{recs[0].k:>4}" in table
    assert len(json.loads(_loom("segments", reference, "--json").stdout)) == len(recs)
    assert (reference / "segments" / "segments.png").stat().st_size > 0  # Fig. 6 and the F_max steps
    assert (reference / "segments" / "segment-000.aqm.png").stat().st_size > 0  # M_AQM at K


def test_cluster_gives_the_same_records_and_frames(room, reference):
    tmp, scene, config = room
    out = tmp / "cluster"
    said = _loom(*[a for a in _render_args(scene, out, config, "--scheduler", "local", "--workers", "2")
                   if a != "--quiet"]).stdout
    assert re.search(r"dask dashboard: http://127\.0\.0\.1:\d+/status", said), said  # the link loom render prints
    assert _records(out) == _records(reference)
    assert _frames(out) == _frames(reference)


def test_keeping_the_hit_records_changes_no_decision_and_no_bit(room, reference):
    """--keep-records stores the records beside the counts and sums a render reads: the same
    segment records and frames as the default store of counts and sums alone."""
    tmp, scene, config = room
    out = tmp / "records"
    _loom(*_render_args(scene, out, config, "--scheduler", "synchronous", "--keep-records"))
    assert _records(out) == _records(reference)
    assert _frames(out) == _frames(reference)
    assert any((out / "photons.zarr" / "frames").rglob("c.0.0"))
    assert not (reference / "photons.zarr" / "frames").exists()


def test_a_killed_render_resumes_to_the_same_result(room, reference):
    tmp, scene, config = room
    out = tmp / "killed"
    cmd = [sys.executable, "-m", "pipeline", *map(str, _render_args(scene, out, config, "--scheduler", "synchronous"))]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None:
        rec = read_record(out, 0) if (out / "segments").is_dir() else None
        if rec is not None and rec.status == "done":  # killed while segment 1 is under way
            proc.send_signal(signal.SIGKILL)
            break
        time.sleep(0.05)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL, "the render finished before it could be killed"
    _loom(*_render_args(scene, out, config, "--scheduler", "synchronous"))
    assert _records(out) == _records(reference)
    assert _frames(out) == _frames(reference)


def test_reprocessing_a_segment_touches_exactly_its_frames(room, reference):
    tmp, scene, config = room
    out = tmp / "redo"
    shutil.copytree(reference, out)
    recs = read_records(out)
    seg = recs[1]
    stamps = {f: frame_paths(out, f)[0].stat().st_mtime_ns for f in range(60, 81)}
    before = _frames(out)
    time.sleep(0.01)
    _loom(*_render_args(scene, out, config, "--scheduler", "synchronous", "--segment", "1"))
    after = {f: frame_paths(out, f)[0].stat().st_mtime_ns for f in range(60, 81)}
    redone = {f for f in stamps if after[f] != stamps[f]}
    assert redone == set(range(seg.start, seg.end + 1))
    assert _frames(out) == before  # the same settings give the same bits
    assert _records(out) == _records(reference)


def test_camera_only_motion_traces_one_photon_set(tmp_path):
    from pipeline.store import PhotonStore

    scene = tmp_path / "static.glb"
    _loom("scene", "static", "-o", scene)
    config = tmp_path / "c.json"
    config.write_text(json.dumps({"pilot_photons": 4000, "n_frame_max": 32000, "d_thr": 0.3}))
    out = tmp_path / "out"
    _loom("render", scene, "--frames", "1-30", "--out", out, "--resolution", "48x36", "--spp", "1",
          "--config", config, "--scheduler", "synchronous", "--quiet")
    (rec,) = read_records(out)
    assert (rec.start, rec.end, rec.fmax, rec.temporal) == (1, 30, 0, "off") and not rec.fmax_steps
    store = PhotonStore.open(out / "photons.zarr")
    assert all(store.source_frame(f) == 0 for f in range(30))
    report = json.loads((out / "report.json").read_text())
    # every batch traced belongs to the one photon set, which holds just what the loop asked for
    assert report["photon_batches_traced"] == len(store.done_batches(0))
    assert store.photons_emitted(0) == max(rec.n_frame, 4000)


def test_changing_d_thr_re_decides_without_tracing_again(room, reference):
    tmp, scene, config = room
    out = tmp / "redecide"
    shutil.copytree(reference, out)
    lenient = tmp / "lenient.json"
    lenient.write_text(json.dumps({**CHEAP, "d_thr": 0.95}))  # the first N_frame passes everywhere
    _loom(*_render_args(scene, out, lenient, "--scheduler", "synchronous"))
    old, new = read_records(reference), read_records(out)
    assert all(r.decision_hash != old[0].decision_hash for r in new)
    assert all(len(r.n_frame_steps) == 1 for r in new)
    report = json.loads((out / "report.json").read_text())
    assert report["photon_batches_traced"] == 0  # the pilot's N_frame is a prefix of what is stored
    assert sorted(p.name for p in (out / "segments").glob("segment-*.json")) == [
        f"segment-{r.index:03d}.json" for r in new]
