"""Segment records: what the planner decided for each animation segment, on disk (§5.2, Table 1).

One JSON file a segment, ``OUT/segments/segment-NNN.json``, written through a temporary file and
``os.replace`` (atomic on POSIX), so a kill leaves the old record or the new one, never half of
one. A record is *decided* once Steps 1-3 are done (its photons are all traced) and *done* once
its frames are written. ``decision_hash`` is the digest of everything the decisions read (scene,
photon, collection, filter and segment settings, the render's look): a record whose hash differs
from the run's is stale and re-decided, while the photons it shot stay in the store and are reused.

``loom segments OUT`` prints them as the paper's Table 1 (K_i, N_frame, F_max) with d_AQM, p_me
and the time of each step.
"""
from __future__ import annotations

import json
import math
import os
import re
from dataclasses import asdict, dataclass, field
from pathlib import Path

from pipeline.errors import LoomError

from .decisions import frame_photons

DIRECTORY = "segments"
STATUSES = ("decided", "done")
# Fields older records hold that the code no longer writes: dropped on reading, so `loom segments`
# still shows such a record and a rerun finds it stale (its decision_hash digests settings that are
# gone) and decides the segment again, reusing its photons. Any other unknown field is refused.
# fmax_checks: the F_max checks of the deleted fmax_pays switch (docs/11-defaults.md).
RETIRED_FIELDS = ("fmax_checks",)


@dataclass
class SegmentRecord:
    index: int
    start: int  # first frame of the segment
    end: int  # last frame
    k: int  # central frame K (§5.2, Fig. 2)
    fmax: int  # F_max used by every frame of the segment (§5.2.2)
    n_frame: int  # N_frame of every frame (§5.2.3); end frames get end_factor x this
    temporal: str  # adaptive | fixed | off (kernels/temporal.py)
    guided: bool  # decided by the loops (True) or given with --photons N --fmax F (False)
    decision_hash: str
    status: str = "decided"
    end_frames: list = field(default_factory=list)  # frames within F_max/2 of an animation end or a step
    steps: list = field(default_factory=list)  # frames beginning after a lighting step (decisions.lighting_steps)
    end_factor: float = 1.0
    pilot: dict = field(default_factory=dict)  # frame, n_probe, e_probe, e_target, n_pilot (§5.2.1)
    fmax_steps: list = field(default_factory=list)  # [{fmax, k, p_me_back, p_me_fwd}] (§5.2.2)
    n_frame_steps: list = field(default_factory=list)  # [{n_frame, d_aqm}] (§5.2.3), d_aqm in %
    capped: bool = False  # the doubling loop stopped at n_frame_max with d_AQM > d_thr
    windows_at_k: dict = field(default_factory=dict)  # Fig. 5 at K's last d_AQM (planner.window_histogram)
    # F_max of the windows that reconstruct the frames (decisions.window_fmax_loop); None: fmax
    window_fmax: int | None = None
    window_fmax_steps: list = field(default_factory=list)  # [{fmax, d_aqm}], d_aqm in %
    frames: dict = field(default_factory=dict)  # str(frame) -> {adaptation, digest, filtered, window}
    times_s: dict = field(default_factory=dict)
    # bytes its tasks read and wrote through the store, by task kind (pipeline/store counting_io):
    # like the times, they depend on which worker's caches held what
    io_bytes: dict = field(default_factory=dict)

    def targets(self) -> dict[int, int]:
        """Photons each frame of the segment traces (pipeline/segments/decisions.photon_targets)."""
        ends = set(self.end_frames)
        return {f: frame_photons(self.n_frame, self.end_factor if f in ends else 1.0)
                for f in range(self.start, self.end + 1)}

    @property
    def windows_fmax(self) -> int:
        """F_max of the windows the segment's frames are collected with."""
        return self.fmax if self.window_fmax is None else self.window_fmax

    @property
    def fmax_text(self) -> str:
        """"44", or "44 (windows 30)" where the windows are shorter than the segment's F_max."""
        return f"{self.fmax}" if self.windows_fmax == self.fmax else f"{self.fmax} (windows {self.windows_fmax})"

    @property
    def without_indirect_light(self) -> bool:
        """Neither the pilot nor the segment's frames recorded indirect light: the segment stayed on
        the smallest rung (decisions.unlit_n_frame)."""
        return bool(self.pilot.get("no_indirect_light"))

    @property
    def e_pilot_text(self) -> str:
        """The pilot's E (§5.2.1): "0.412"; "none" where its photons recorded no indirect light
        (stored as null: E would be infinite, and JSON has no infinity); "-" without a pilot."""
        if not self.pilot:
            return "-"
        e = self.pilot.get("e_probe")
        return "none" if e is None or not math.isfinite(e) else f"{e:.3f}"

    @property
    def d_aqm(self) -> float | None:
        return self.n_frame_steps[-1]["d_aqm"] if self.n_frame_steps else None

    def to_dict(self) -> dict:
        return asdict(self)

    def without_times(self) -> dict:
        """The record as data, minus what a clock or a worker's caches decide (for determinism checks)."""
        d = self.to_dict()
        d.pop("times_s")
        d.pop("io_bytes")
        return d

    @classmethod
    def from_dict(cls, data: dict) -> "SegmentRecord":
        return cls(**{k: v for k, v in data.items() if k not in RETIRED_FIELDS})


def used_fmax_step(r: SegmentRecord) -> dict:
    """The Step 2 step of the F_max the segment kept ({} without one)."""
    return next((s for s in reversed(r.fmax_steps) if s["fmax"] == r.fmax), {})


def record_path(out_dir: str | Path, index: int) -> Path:
    return Path(out_dir) / DIRECTORY / f"segment-{index:03d}.json"


def record_index(path: str | Path) -> int | None:
    """The segment index of a file of the records folder (record, picture, farm chunk), or None."""
    m = re.match(r"segment-(\d+)[.]", Path(path).name)
    return int(m[1]) if m else None


def write_record(out_dir: str | Path, record: SegmentRecord) -> None:
    path = record_path(out_dir, record.index)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.partial")
    tmp.write_text(json.dumps(record.to_dict(), indent=1, sort_keys=True))
    os.replace(tmp, path)


def read_record(out_dir: str | Path, index: int) -> SegmentRecord | None:
    """The record of segment ``index``, or None if there is none; a broken file is an error."""
    path = record_path(out_dir, index)
    if not path.is_file():
        return None
    try:
        return SegmentRecord.from_dict(json.loads(path.read_text()))
    except (ValueError, TypeError) as err:
        raise LoomError(f"not a segment record ({err})", path=str(path)) from None


def read_records(out_dir: str | Path) -> list[SegmentRecord]:
    """Every record under ``OUT/segments`` in segment order."""
    folder = Path(out_dir) / DIRECTORY
    if not folder.is_dir():
        raise LoomError("has no segment records (render it with loom render first)", path=str(out_dir))
    out = []
    for path in sorted(folder.glob("segment-*.json")):
        if not re.fullmatch(r"segment-\d+\.json", path.name):
            continue  # a farm's chunk files (pipeline/run/farm.py) sit beside the records
        rec = read_record(out_dir, record_index(path))
        if rec is not None:
            out.append(rec)
    return out


# What `loom segments` and the report say under a segment the doubling loop stopped at its cap
CAPPED_NOTE = ("N_frame reached n_frame_max with d_AQM still above d_thr: raise n_frame_max (--config), or see "
               "whether coarser elements hide the noise at a bias under d_thr (`loom bench elements`)")


def table(records: list[SegmentRecord]) -> list[str]:
    """The paper's Table 1 with the evidence: K_i, N_frame, F_max, d_AQM, p_me, pilot E, times."""
    head = (f"{'seg':>3} {'frames':>9} {'K':>4} {'N_frame':>9} {'F_max':>5} {'d_AQM %':>8} "
            f"{'p_me back/fwd':>13} {'E pilot':>8} {'status':>8} {'s (init, F_max, N_frame, frames)':>34}")
    lines = [head]
    for r in records:
        last = used_fmax_step(r)
        p = f"{last.get('p_me_back', float('nan')):.2f}/{last.get('p_me_fwd', float('nan')):.2f}" \
            if last else "-"
        d = f"{r.d_aqm:.2f}" if r.d_aqm is not None else "-"
        e = r.e_pilot_text
        t = r.times_s
        times = ", ".join(f"{t.get(k, 0.0):.1f}" for k in ("init_s", "fmax_s", "n_frame_s", "frames_s"))
        status = r.status + ("*" if r.capped else "")
        lines.append(f"{r.index:>3} {f'{r.start}-{r.end}':>9} {r.k:>4} {r.n_frame:>9,} {r.fmax:>5} {d:>8} "
                     f"{p:>13} {e:>8} {status:>8} {times:>34}")
        if r.n_frame_steps:
            steps = ", ".join(f"{s['n_frame']:,}: {s['d_aqm']:.2f} %" for s in r.n_frame_steps)
            lines.append(f"{'':>4}N_frame steps (d_AQM at K): {steps}")
        if r.window_fmax_steps:
            tries = ", ".join(f"{s['fmax']}: {s['d_aqm']:.2f} %" for s in r.window_fmax_steps)
            lines.append(f"{'':>4}windows' F_max {r.windows_fmax} (tried, d_AQM at K): {tries}")
        if len(r.fmax_steps) > 1:
            steps = ", ".join(f"{s['fmax']} ({s['p_me_back']:.2f}/{s['p_me_fwd']:.2f})" for s in r.fmax_steps)
            lines.append(f"{'':>4}F_max steps (p_me back/fwd): {steps}")
    if any(r.capped for r in records):
        lines.append(f"* {CAPPED_NOTE}")
    return lines
