"""Table 2's rows from segment records (pipeline/report/tables.stage_table): every stage's wall
time split by its tasks' core time, known answers on made-up clocks."""
from __future__ import annotations

from types import SimpleNamespace

import pytest

from pipeline.report.tables import stage_table


def _record(**times):
    return SimpleNamespace(times_s=times, io_bytes={})  # stage_table reads a record's times and bytes


def test_rows_split_each_stage_by_core_time_and_add_up_to_the_wall_time():
    # Shoot 10 s wall: tracing 6, store writes 3, batch sums 1 core-s. Frames stage 10 s wall, which the
    # coordinator's clock split 3 (until the last reconstruction) + 7, while the tasks' core time was
    # 2 s of reconstruction (0.5 of it reading and writing) and 8 s of compositing.
    records = [_record(shoot_s=6.0, temporal_s=2.0, composite_s=3.0, task_pose_s=0.5, task_trace_s=3.5,
                       task_write_s=1.5, task_sums_s=0.5, task_reconstruct_windows_s=1.0,
                       task_reconstruct_read_s=0.25, task_composite_render_s=3.0, task_composite_write_s=1.0),
               _record(shoot_s=4.0, temporal_s=1.0, composite_s=4.0, task_trace_s=2.0, task_write_s=1.5,
                       task_sums_s=0.5, task_reconstruct_sums_s=0.5, task_reconstruct_map_write_s=0.25,
                       task_composite_load_s=1.0, task_composite_render_s=3.0)]
    wall = stage_table(records)["wall"]
    assert wall["photon tracing"] == pytest.approx(6.0)
    assert wall["I/O"] == pytest.approx(3.0 + 0.5)  # the shoot's writes, and the reconstruction's quarter of 2 s
    assert wall["temporal processing"] == pytest.approx(2.0 - 0.5 + 1.0)  # plus the shoot's batch sums
    assert wall["ray tracing"] == pytest.approx(8.0)
    assert wall["AQM"] == 0.0
    assert wall["total indirect"] == pytest.approx(12.0)
    assert wall["total indirect"] + wall["ray tracing"] == pytest.approx(10.0 + 10.0)
    core = stage_table(records)["core"]
    assert core["photon tracing"] == pytest.approx(6.0) and core["ray tracing"] == pytest.approx(8.0)
    assert core["I/O"] == pytest.approx(3.5) and core["temporal processing"] == pytest.approx(2.5)


def test_without_composites_the_temporal_clock_stands():
    wall = stage_table([_record(temporal_s=3.0, task_reconstruct_windows_s=2.0)])["wall"]
    assert wall["temporal processing"] == pytest.approx(3.0) and wall["ray tracing"] == 0.0


def test_the_io_row_says_the_bytes_read_and_written():
    """The bytes of the I/O row: what the shoot and reconstruction tasks read and wrote, summed
    over the segment records (pipeline/store counting_io)."""
    records = [SimpleNamespace(times_s={}, io_bytes={"shoot_write_bytes": 300, "shoot_read_bytes": 20,
                                                     "reconstruct_read_bytes": 500, "reconstruct_write_bytes": 7}),
               SimpleNamespace(times_s={}, io_bytes={"shoot_write_bytes": 100})]
    assert stage_table(records)["bytes"] == {"read": 520, "written": 407}
