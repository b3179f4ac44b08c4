"""The numbers the report prints and `loom bench render` measures: the paper's Table 2 per stage from
a run's segment records (:func:`stage_table`), and the photon store's size in one line."""
from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Iterable

    from pipeline.segments.records import SegmentRecord

ROWS = ("photon tracing", "AQM", "temporal processing", "I/O", "total indirect", "ray tracing")
IO_KEYS = ("task_reconstruct_read_s", "task_reconstruct_map_write_s")


def stage_table(records: Iterable[SegmentRecord]) -> dict:
    """Table 2 in seconds (wall) and core-seconds from a run's segment records."""
    t: dict[str, float] = {}
    for r in records:
        for k, v in r.times_s.items():
            t[k] = t.get(k, 0.0) + float(v)
    g = t.get
    shoot, aqm, temporal, composite = g("shoot_s", 0.0), g("aqm_s", 0.0), g("temporal_s", 0.0), g("composite_s", 0.0)
    decide_rest = max(0.0, g("decide_s", 0.0) - shoot - aqm)
    trace_core = g("task_pose_s", 0.0) + g("task_trace_s", 0.0)
    write_core = g("task_write_s", 0.0)
    sums_core = g("task_sums_s", 0.0)  # the batch sums the shoot tasks make (pipeline/collection/batch_sums.py)
    shoot_core = trace_core + write_core + sums_core
    rec_core = sum(v for k, v in t.items() if k.startswith("task_reconstruct_"))
    rec_io_core = sum(g(k, 0.0) for k in IO_KEYS)
    composite_core = sum(g(f"task_composite_{k}_s", 0.0) for k in ("load", "render", "write"))
    if rec_core > 0 and composite_core > 0:  # the frames stage's wall time, split by core time
        frames_wall = temporal + composite
        temporal = frames_wall * rec_core / (rec_core + composite_core)
        composite = frames_wall - temporal
    shoot_io = shoot * write_core / shoot_core if shoot_core > 0 else 0.0
    shoot_sums = shoot * sums_core / shoot_core if shoot_core > 0 else 0.0
    rec_io = temporal * rec_io_core / rec_core if rec_core > 0 else 0.0
    wall = {"photon tracing": shoot - shoot_io - shoot_sums, "AQM": aqm,
            "temporal processing": temporal - rec_io + shoot_sums + decide_rest,
            "I/O": shoot_io + rec_io, "ray tracing": composite}
    core = {"photon tracing": trace_core, "AQM": aqm,
            "temporal processing": rec_core - rec_io_core + sums_core + decide_rest,
            "I/O": write_core + rec_io_core,
            "ray tracing": composite_core}
    for d in (wall, core):
        d["total indirect"] = sum(d[k] for k in ("photon tracing", "AQM", "temporal processing", "I/O"))
    return {"wall": wall, "core": core, "times": t, "bytes": io_bytes(records)}


def io_bytes(records: Iterable[SegmentRecord]) -> dict[str, int]:
    """Bytes the I/O row moved (the segment records' ``io_bytes``, pipeline/store counting_io):
    ``written`` by the shoot tasks (counts, sums, records if kept) and the reconstructions (maps),
    ``read`` by both (the previous batch's counts; the sums and counts the windows reach)."""
    out = {"read": 0, "written": 0}
    for r in records:
        for k, v in r.io_bytes.items():
            out["read" if k.endswith("read_bytes") else "written"] += int(v)
    return out


def store_size_line(size: dict) -> str:
    """One line of ``pipeline/run/render.store_size``: what the store holds and what a photon costs."""
    parts = size["bytes"]
    if parts is None or not size["photons"]:
        return f"photon store: {size['photons']:,} photons"
    kept = f", hit records {parts['records'] / 1e6:,.1f} MB" if size["keep_records"] else " (no hit records)"
    return (f"photon store {(parts['photons'] + parts['records']) / 1e6:,.1f} MB for {size['photons']:,} photons, "
            f"{size['bytes_per_photon']:.2f} bytes a photon{kept}; illumination maps {parts['maps'] / 1e6:,.1f} MB")
