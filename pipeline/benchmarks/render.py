"""``loom bench render``: the paper's Table 2 (§6) per frame, and the scaling of a whole render.

Three renders of the scene (default the built-in ROOM, all its frames, 320x240, loom render's spp,
``RenderSettings.spp``), each into a fresh output directory on a LocalCluster:

* (a) guided: ``--photons auto`` (``render(..., n_photons=None)``), ``--workers`` workers;
* (b) fixed N_frame = 40,000, F_max = 30, adaptive collection, on 1 worker and on ``--workers``.

Table 2 rows, from the segment records (pipeline/segments/records.py, ``times_s``) of one run:
wall-clock stage times ``shoot_s``, ``aqm_s``, ``temporal_s`` (the reconstruction tasks),
``composite_s``, and the decisions' remainder (``decide_s`` less its shooting and AQM: pilot
error and p_me windows, counted as temporal processing). The tasks' own timings (summed over
workers: ``task_*``) split a stage's wall time in proportion: photon tracing = shoot x
(pose + trace) / (pose + trace + store write); I/O = the store write's part of the shoot and the
record reads and map writes' part of the reconstruction. The frames stage runs a segment's
reconstructions and composites at once (pipeline/run/coordinator.py ``frames``: a chunk's frames are
composited while later chunks are reconstructed), so its wall time (``temporal_s`` +
``composite_s``) is split between them the same way, by their tasks' core time: the coordinator's
own clock runs ``temporal_s`` until the last reconstruction ends, and on two workers that counted
the other worker's compositing meanwhile as temporal time (ROOM, 40,000 photons: 2.4-2.8 s of
``temporal_s`` on 2 workers against 1.4 s on one, for 3.2 s of reconstruction tasks' core time).
Total indirect = tracing + AQM + temporal + I/O; ray tracing is the compositing stage
(rendering, tone mapping, EXR and PNG). Per frame = divided by the frames rendered; shares are of
indirect + ray tracing. "core s" is the tasks' summed time per frame (what one core would spend).

Scaling: the wall time of the whole fixed render (``render()``, cluster start-up included) on 1
worker against ``--workers``, and the same without the cluster start-up and video (the
segments' wall time). On a shared machine identical runs vary by 10-20 %, and the load drifts
between the two runs of a pair, so ``--repeat N`` runs N pairs in ABBA order (1 worker first in
even pairs, ``--workers`` first in odd ones) and reports every pair's ratio, their median and
the median's distribution-free confidence interval (pipeline/benchmarks/median_interval.py); the
tables are those of the median pair. What the machine charged for fresh memory and new files
before and after the renders is printed too (pipeline/benchmarks/machine.py):
on the shared build machines it moves the I/O row by 2x between runs of the same bits.
"""
from __future__ import annotations

import json
import statistics
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING

import click

from pipeline.frames.settings import RenderSettings
from pipeline.report.tables import ROWS, stage_table, store_size_line
from pipeline.run.cluster import connect
from pipeline.run.render import RenderRequest, render
from pipeline.scene.builtin import BUILTIN_SCENES, write_builtin
from pipeline.segments.records import read_records

from .machine import announce
from .median_interval import median_interval

if TYPE_CHECKING:
    from collections.abc import Callable


def run_render(scene: Path, out: Path, *, frames: str | None, width: int, height: int, spp: int, workers: int,
               n_photons: int | None, fmax: int | None) -> dict:
    t0 = time.perf_counter()
    report = render(RenderRequest(scene_path=scene, frames=frames, out_dir=out,
                                  settings=RenderSettings(width=width, height=height, spp=spp), n_photons=n_photons,
                                  fmax=fmax, temporal="adaptive"), scheduler="local", workers=workers)
    wall = time.perf_counter() - t0
    records = read_records(out)
    table = stage_table(records)
    segments_wall = sum(r.times_s.get("decide_s", r.times_s.get("init_s", 0.0)) + r.times_s.get("frames_s", 0.0)
                        for r in records)
    return {"wall_s": wall, "segments_wall_s": segments_wall, "frames": len(report["rendered"]),
            "segments": report["segments"], "table": table, "report_times": report["times_s"],
            "store_size": report["store_size"]}


def _print_table(echo: Callable[[str], None], title: str, run: dict) -> None:
    n = max(run["frames"], 1)
    wall, core = run["table"]["wall"], run["table"]["core"]
    total = wall["total indirect"] + wall["ray tracing"]
    n_frame = ", ".join(f"{s['n_frame']:,}" for s in run["segments"])
    fmax = ", ".join(str(s["fmax"]) for s in run["segments"])
    echo(f"\n{title}: {run['frames']} frames, {run['wall_s']:.1f} s wall, {len(run['segments'])} segment(s) "
         f"(N_frame {n_frame}; F_max {fmax})")
    echo(f"  {'stage':<22}{'s/frame':>10}{'share':>9}{'core s/frame':>14}")
    for row in ROWS:
        echo(f"  {row:<22}{wall[row] / n:>10.4f}{100 * wall[row] / total if total else 0:>8.1f}%{core[row] / n:>14.4f}")
    moved = run["table"]["bytes"]
    echo(f"  I/O: {moved['read'] / n / 1e6:.3f} MB read and {moved['written'] / n / 1e6:.3f} MB written a frame; "
         + store_size_line(run["store_size"]))


def _warm_up() -> None:
    """Import what a render's client process imports (distributed, its dashboard, matplotlib) and
    start and close one local cluster (the fork server the workers come from, the scheduler's
    first-time set-up) before the first timed run. The first render in a process paid about 2 s of
    imports and 0.8 s more cluster start-up (0.95 against 0.17 s), which made the first pair's
    first run slower than the others and that pair's ratio wrong."""
    import matplotlib.backends.backend_agg  # noqa: F401
    import matplotlib.figure  # noqa: F401

    with connect("local", 1):
        pass


def run(scene: str = "room", *, frames: str | None = None, width: int = 320, height: int = 240,
        spp: int = RenderSettings.spp, workers: int = 2, n_photons: int = 40_000, fmax: int = 30,
        skip_guided: bool = False, repeat: int = 1,
        json_path: str | Path | None = None, echo: Callable[[str], None] = click.echo) -> dict:
    """The three renders of ``scene`` (a built-in name or a file), their tables and the scaling; returns
    the figures (also written to ``json_path`` if given)."""
    results: dict = {}
    with tempfile.TemporaryDirectory(prefix="loom-bench-render-") as tmp:
        tmp = Path(tmp)
        path = write_builtin(scene, tmp / f"{scene}.glb") if scene in BUILTIN_SCENES else Path(scene)
        common = dict(frames=frames, width=width, height=height, spp=spp)
        echo(f"loom bench render: {Path(path).stem}, {width}x{height}, {spp} spp, LocalCluster")
        results["machine"] = {"before": announce(tmp, "before", echo)}
        if not skip_guided:
            results["guided"] = run_render(path, tmp / "guided", workers=workers, n_photons=None, fmax=None, **common)
            _print_table(echo, f"(a) guided (--photons auto), {workers} workers", results["guided"])
        _warm_up()
        pairs = []
        for i in range(repeat):
            # ABBA order (1 then N, N then 1, ...): a machine that speeds up or slows down steadily
            # favours neither side of the median
            runs = {}
            for n in ((1, workers) if i % 2 == 0 else (workers, 1)):
                runs[n] = run_render(path, tmp / f"fixed{n}-{i}", workers=n, n_photons=n_photons, fmax=fmax,
                                     **common)
            one, many = runs[1], runs[workers]
            pairs.append((one["wall_s"] / many["wall_s"], one["segments_wall_s"] / many["segments_wall_s"], one, many))
            if repeat > 1:
                echo(f"  pair {i + 1}/{repeat}: 1 worker {one['wall_s']:.1f} s, {workers} workers "
                     f"{many['wall_s']:.1f} s: {pairs[-1][0]:.2f}x (segments only {pairs[-1][1]:.2f}x)")
        results["machine"]["after"] = announce(tmp, "after", echo)
    ratio = statistics.median(p[0] for p in pairs)
    ratio_segments = statistics.median(p[1] for p in pairs)
    median_pair = min(pairs, key=lambda p: abs(p[0] - ratio))
    results["fixed_1"], results[f"fixed_{workers}"] = median_pair[2], median_pair[3]
    fixed = results[f"fixed_{workers}"]
    _print_table(echo, f"(b) fixed N_frame {n_photons:,}, F_max {fmax}, {workers} workers", fixed)
    _print_table(echo, f"    fixed N_frame {n_photons:,}, F_max {fmax}, 1 worker", results["fixed_1"])
    one = results["fixed_1"]
    of = f"median of {repeat} alternated pairs" if repeat > 1 else "one pair"
    echo(f"\nscaling, whole render (fixed, {of}): 1 worker {one['wall_s']:.1f} s, {workers} workers "
         f"{fixed['wall_s']:.1f} s: {ratio:.2f}x (segments only: {ratio_segments:.2f}x)")
    interval = median_interval([p[0] for p in pairs])
    if repeat > 1:
        echo("  pairs: " + ", ".join(f"{p[0]:.2f}x" for p in pairs))
        # A target is met only where the whole interval clears it (pipeline/benchmarks/median_interval.py)
        echo(f"  the median lies in {interval.low:.2f}x-{interval.high:.2f}x with probability "
             f"{100 * interval.coverage:.1f} % (order statistics of {interval.n} pairs)")
    results["scaling"] = {"workers": workers, "ratio": ratio, "ratio_segments": ratio_segments,
                          "pairs": [[p[0], p[1]] for p in pairs],
                          "median_interval": {"low": interval.low, "high": interval.high,
                                              "coverage": interval.coverage}}
    if json_path:
        Path(json_path).write_text(json.dumps(results, indent=1, default=str))
    return results
