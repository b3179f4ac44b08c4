"""A make-driven farm render: ``loom plan`` writes ``OUT/Makefile``, ``make -C OUT -j N`` renders.

The targets follow the dependencies of §5.2 and of the coordinator (pipeline/run/coordinator.py):

    shoot-000-C       fixed settings only (--photons N --fmax F, photons that differ between
                      frames): chunk C's frames traced at N, no dependencies, so make -j runs
                      the tracing in parallel as loom render's shoot tasks do
    decide-I          Steps 1-3 of segment I (its photons traced); needs decide-(I-1), since a
                      segment starts after the previous one's end with its F_max; with fixed
                      settings it needs the shoot targets and only writes the record
    reconstruct-I-C   Steps 4-5 for chunk C (16 frames) of segment I; needs decide-I and
                      decide-(I+1): its windows reach the neighbours' photons
    frames-I-C        the composites of chunk C of segment I; needs every reconstruct before it,
                      since the eye's adaptation looks back over all earlier frames
    done-I            segment I's record marked done, its frames' infos merged into it
    finish            the segment figure, preview.mp4 and report.json

Segment boundaries are decided as the render goes, so the plan has targets for as many segments
and chunks as the settings allow at most; a target past the animation's last segment (or past
its segment's last chunk) finds nothing to do. Every recipe is one ``loom farm STEP OUT ...``
command that reads the run from ``OUT/plan.json`` (written by ``loom plan``), exits 0 at once when
its outputs are already there and valid, and writes its stamp ``OUT/.farm/<target>.ok`` last.
Steps run the same functions as ``loom render`` (decisions, reconstruction tasks with the same
chunks, composites), so a farm render gives the same frames, bit for bit.
"""
from __future__ import annotations

import json
import math
import os
import shlex
import sys
import time
from pathlib import Path

from pipeline.errors import LoomError
from pipeline.segments.job import Job
from pipeline.segments.planner import reach_targets
from pipeline.segments.records import read_record, read_records, record_path, write_record
from pipeline.store.illumination import IlluminationMaps
from workers.composite import composite_task
from workers.reconstruct import reconstruct_task

from .cluster import connect
from .coordinator import CHUNK_FRAMES, DaskExecutor, composite_calls
from .render import finish

PLAN = "plan.json"
STAMPS = ".farm"


# --- the plan ------------------------------------------------------------------------------------
def bounds(job: Job) -> tuple[int, int]:
    """(segments, chunks per segment) the plan needs at most. Guided: F_max never falls below the
    first segment's, so no segment has fewer than F_max + 1 frames but the last; and none has more
    than fmax_cap + 1 plus the stub of fewer than fmax_cap/2 + 1 frames it may take in."""
    n = job.last - job.first + 1
    if job.n_photons is not None or job.single_state:
        return 1, max(1, math.ceil(len(job.selection) / CHUNK_FRAMES))
    cap = job.config.segments.fmax_cap
    longest = min(n, cap + 1 + cap // 2 + 1)
    return max(1, math.ceil(n / (job.fmax + 1))), max(1, math.ceil(longest / CHUNK_FRAMES))


def shoot_chunks(job: Job) -> list[list[int]]:
    """Frames of each shoot target: with fixed settings every frame's photons are known before
    any decision (the planner's fixed record traces N_frame for each frame of the selection), so they are
    traced in chunks that make can run side by side; none when the decide step itself must trace
    (guided segments) or when all frames share one photon set (camera-only motion)."""
    if job.n_photons is None or job.single_state:
        return []
    frames = list(job.selection)
    return [frames[i:i + CHUNK_FRAMES] for i in range(0, len(frames), CHUNK_FRAMES)]


def write_plan(job: Job, loom: str | None = None, decide_workers: int = 1) -> Path:
    """``OUT/plan.json`` and ``OUT/Makefile`` for ``job``; returns the Makefile's path.
    ``decide_workers`` > 1: guided decide recipes trace their photons on a LocalCluster of that many
    workers (decisions are sequential, nothing else of a segment can run before them, so a farm may
    give a decide target a whole machine); 1: in the recipe's own process. Fixed settings trace in
    the shoot targets instead (:func:`shoot_chunks`)."""
    out = Path(job.out_dir)
    loom = loom or str(Path(sys.executable).with_name("loom"))
    if not 1 <= decide_workers <= 1024:
        raise LoomError(f"must be in [1, 1024], got {decide_workers}", field="--decide-workers")
    _atomic(out / PLAN, json.dumps({"job": job.to_dict(), "decide_workers": decide_workers}, indent=1,
                                   sort_keys=True))
    segments, chunks = bounds(job)
    d = shlex.quote(str(out.resolve()))
    ok = lambda name: f"{STAMPS}/{name}.ok"  # noqa: E731
    lines = [
        f"# photonloom farm plan of {job.scene_path}, frames {job.first}-{job.last} (written by `loom plan`;",
        "# run it again to change settings). make -j N renders; make -k goes on past a failure; make -q",
        "# says whether all is done. Send recipes elsewhere with SHELL or a wrapper, e.g.",
        "#   make -j 8 LOOM='srun -N1 -n1 loom'",
        f"LOOM ?= {shlex.quote(loom)}",
        "",
        ".PHONY: all",
        f"all: {ok('finish')}",
        "",
    ]

    def rule(target: str, needs: list[str], command: str) -> None:
        lines.append(f"{ok(target)}: {' '.join(ok(n) for n in needs)}".rstrip())
        lines.append(f"\t$(LOOM) farm {command}")
        lines.append("")

    shoots = [f"shoot-000-{c:02d}" for c in range(len(shoot_chunks(job)))]
    for c, target in enumerate(shoots):
        rule(target, [], f"shoot {d} 0 {c}")
    for i in range(segments):
        rule(f"decide-{i:03d}", [f"decide-{i - 1:03d}"] if i else shoots, f"decide {d} {i}")
    for i in range(segments):
        neighbours = [f"decide-{i:03d}"] + ([f"decide-{i + 1:03d}"] if i + 1 < segments else [])
        for c in range(chunks):
            rule(f"reconstruct-{i:03d}-{c:02d}", neighbours, f"reconstruct {d} {i} {c}")
    for i in range(segments):
        for c in range(chunks):
            earlier = [f"reconstruct-{j:03d}-{e:02d}" for j in range(i + 1) for e in range(chunks)
                       if j < i or e <= c]
            rule(f"frames-{i:03d}-{c:02d}", earlier, f"frames {d} {i} {c}")
        rule(f"done-{i:03d}", [f"frames-{i:03d}-{c:02d}" for c in range(chunks)], f"done {d} {i}")
    rule("finish", [f"done-{i:03d}" for i in range(segments)], f"finish {d}")
    path = out / "Makefile"
    _atomic(path, "\n".join(lines))
    return path


def _plan(out_dir) -> dict:
    path = Path(out_dir) / PLAN
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise LoomError("has no plan (run `loom plan` first)", path=str(out_dir)) from None
    except ValueError as err:
        raise LoomError(f"not a photonloom plan ({err})", path=str(path)) from None


def load_job(out_dir: str | Path) -> Job:
    path = Path(out_dir) / PLAN
    try:
        return Job.from_dict(json.loads(path.read_text())["job"])
    except FileNotFoundError:
        raise LoomError("has no plan (run `loom plan` first)", path=str(out_dir)) from None
    except (ValueError, KeyError, TypeError) as err:
        raise LoomError(f"not a plan this version of photonloom reads ({err}): run `loom plan` again",
                        path=str(path)) from None


# --- the steps -----------------------------------------------------------------------------------
def step(name: str, out_dir: str | Path, *args: int) -> str:
    """Run one farm step; returns what it did (one line). Writes the step's stamp last."""
    job = load_job(out_dir)
    run = {"shoot": _shoot, "decide": _decide, "reconstruct": _reconstruct, "frames": _frames, "done": _done,
           "finish": _finish}[name]
    said = run(job, *args)
    target = "-".join([name] + [f"{a:03d}" if k == 0 else f"{a:02d}" for k, a in enumerate(args)])
    stamp = Path(job.out_dir) / STAMPS / f"{target}.ok"
    stamp.parent.mkdir(parents=True, exist_ok=True)
    _atomic(stamp, said + "\n")
    return said


def _segment(job: Job, i: int):
    """Segment i's current record, None when the animation ended before it; an error when the
    segment before it is not decided (its target did not run)."""
    if i:
        prev = _current(job, i - 1)
        if prev is None:
            return None, None
        if prev.end >= job.last:
            return None, prev
    rec = read_record(job.out_dir, i)
    return (rec if rec is not None and rec.decision_hash == job.decision_hash else None), None


def _current(job: Job, i: int):
    rec = read_record(job.out_dir, i)
    if rec is None or rec.decision_hash != job.decision_hash:
        raise LoomError(f"segment {i} is not decided for this plan (run its decide target first)",
                        path=str(record_path(job.out_dir, i)))
    return rec


def _shoot(job: Job, i: int, c: int) -> str:
    """Chunk ``c``'s photons at the fixed N_frame, traced in this process; frames whose batches
    are already stored are skipped (``DaskExecutor.shoot``), so a rerun traces nothing."""
    chunks = shoot_chunks(job)
    if i or c >= len(chunks):
        return f"segment {i} chunk {c}: no photons to trace here"
    run = DaskExecutor(job, None)
    run.shoot({f: job.n_photons for f in chunks[c]})
    what = f"{run.batches_traced} batch(es) traced" if run.batches_traced else "already traced"
    return f"segment {i} chunk {c}: frames {chunks[c][0]}-{chunks[c][-1]} {what}"


def _decide(job: Job, i: int) -> str:
    if i and (job.n_photons is not None or job.single_state):
        return f"segment {i}: none (one segment)"
    prev = _current(job, i - 1) if i else None
    if prev is not None and prev.end >= job.last:
        return f"segment {i}: none (the animation ends in segment {i - 1})"
    # With fixed settings the shoot targets traced the photons: nothing for workers to do
    workers = 1 if shoot_chunks(job) else int(_plan(job.out_dir).get("decide_workers", 1))
    start, fmax = (job.first, job.fmax) if prev is None else (prev.end + 1, prev.fmax)
    with connect("synchronous" if workers == 1 else "local", workers) as client:
        rec = DaskExecutor(job, client).planner().record(i, start, fmax)
    return f"segment {i}: frames {rec.start}-{rec.end}, K {rec.k}, F_max {rec.fmax}, N_frame {rec.n_frame:,}"


def _chunk_path(job: Job, i: int, c: int) -> Path:
    return record_path(job.out_dir, i).with_suffix(f".chunk-{c:02d}.json")


def _calls(job: Job, i: int):
    rec, _ = _segment(job, i)
    if rec is None:
        return None, []
    if rec.end < job.last and rec.guided:
        _current(job, i + 1)  # its decide target must have run: the windows reach its photons
    return rec, DaskExecutor(job, None).reconstruct_calls(rec, reach_targets(job, rec))


def _reconstruct(job: Job, i: int, c: int) -> str:
    _, calls = _calls(job, i)
    if c >= len(calls):
        return f"segment {i} chunk {c}: none"
    request = calls[c][1]
    frames = request.frames
    path = _chunk_path(job, i, c)
    if path.is_file():
        saved = json.loads(path.read_text())
        maps = IlluminationMaps.open(job.store_url)
        if saved.get("decision_hash") == job.decision_hash and all(maps.is_done(f - 1) for f in frames):
            return f"segment {i} chunk {c}: frames {frames[0]}-{frames[-1]} already reconstructed"
    result = reconstruct_task(request)
    _atomic(path, json.dumps({"decision_hash": job.decision_hash, "frames": result["frames"],
                              "times": result.get("times", {})}, sort_keys=True))
    return f"segment {i} chunk {c}: frames {frames[0]}-{frames[-1]} reconstructed"


def _infos(job: Job, upto: tuple[int, int]) -> dict[int, dict]:
    """Frame infos of every chunk up to (segment, chunk), from the chunk files."""
    info: dict[int, dict] = {}
    for i in range(upto[0] + 1):
        _, calls = _calls(job, i)
        for c in range(len(calls) if i < upto[0] else min(upto[1] + 1, len(calls))):
            path = _chunk_path(job, i, c)
            if not path.is_file():
                raise LoomError("missing (run its reconstruct target first)", path=str(path))
            info.update({int(f): v for f, v in json.loads(path.read_text())["frames"].items()})
    return info


def _frames(job: Job, i: int, c: int) -> str:
    _, calls = _calls(job, i)
    if c >= len(calls):
        return f"segment {i} chunk {c}: none"
    frames = calls[c][1].frames
    todo = composite_calls(job, frames, _infos(job, (i, c)))
    for _, request in todo:
        composite_task(request)
    return f"segment {i} chunk {c}: {len(todo)} of frames {frames[0]}-{frames[-1]} written"


def _done(job: Job, i: int) -> str:
    rec, calls = _calls(job, i)
    if rec is None:
        return f"segment {i}: none"
    if rec.status != "done":
        frames: dict = {}
        for c in range(len(calls)):
            frames.update(json.loads(_chunk_path(job, i, c).read_text())["frames"])
        rec.frames, rec.status = frames, "done"
        write_record(job.out_dir, rec)
    return f"segment {i}: done"


def _finish(job: Job) -> str:
    report = finish(job, read_records(job.out_dir), None, time.perf_counter())
    return f"finished: {report['video']}"


def _atomic(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.partial")
    tmp.write_text(text)
    os.replace(tmp, path)
