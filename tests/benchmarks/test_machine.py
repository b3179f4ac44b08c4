"""pipeline/benchmarks/machine.py: the machine's costs are measured for real and leave nothing behind."""
import math

import pytest

from pipeline.benchmarks.machine import announce, describe, first_touch_us, machine_costs, new_file_ms


def test_costs_are_finite_positive_and_leave_no_file(tmp_path):
    costs = machine_costs(tmp_path)
    assert set(costs) == {"new_file_ms", "first_touch_us"}
    assert all(math.isfinite(v) and v > 0 for v in costs.values())
    assert list(tmp_path.iterdir()) == []
    assert "ms" in describe(costs) and "us a page" in describe(costs)
    lines = []
    again = announce(tmp_path, "before", lines.append)
    assert set(again) == set(costs) and lines == [f"machine before: {describe(again)}"]
    assert list(tmp_path.iterdir()) == []


def test_a_bigger_file_costs_more_to_write(tmp_path):
    # 64 times the bytes: the write must be dearer whatever the file system's speed
    assert new_file_ms(tmp_path, size=64 << 20, count=3) > new_file_ms(tmp_path, size=1 << 20, count=3)
    assert list(tmp_path.iterdir()) == []


def test_an_unwritable_directory_leaves_nothing_and_raises(tmp_path):
    with pytest.raises(FileNotFoundError):
        new_file_ms(tmp_path / "missing")
    with pytest.raises(ValueError):
        new_file_ms(tmp_path, size=0)
    with pytest.raises(ValueError):
        first_touch_us(0)
