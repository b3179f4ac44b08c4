"""Frame ranges in render-farm syntax and the frame-to-time mapping."""
from __future__ import annotations

import pytest

from pipeline.errors import LoomError
from pipeline.scene import Timeline, parse_frame_range


@pytest.mark.parametrize(
    "spec, frames",
    [
        ("1-5", [1, 2, 3, 4, 5]),
        ("1-10x3", [1, 4, 7, 10]),
        ("1,5,10-12", [1, 5, 10, 11, 12]),
        ("7", [7]),
        ("3-4, 1", [1, 3, 4]),
        ("1-3,2-4", [1, 2, 3, 4]),
    ],
)
def test_parse_frame_range(spec, frames):
    assert parse_frame_range(spec) == frames


@pytest.mark.parametrize("spec", ["", "a-b", "5-1", "1-10x0", "1--3", "1-3y2"])
def test_bad_frame_range(spec):
    with pytest.raises(LoomError, match="frames"):
        parse_frame_range(spec) if spec else Timeline(30, 10).select("x")


def test_timeline_maps_frames_to_time_and_checks_bounds():
    tl = Timeline(fps=30.0, frames=135)
    assert tl.time(1) == 0.0 and tl.time(31) == pytest.approx(1.0)
    assert tl.duration == pytest.approx(134 / 30)
    assert tl.select(None) == list(range(1, 136))
    assert tl.select("100-135x5") == [100, 105, 110, 115, 120, 125, 130, 135]
    with pytest.raises(LoomError, match="136 is outside the timeline 1-135"):
        tl.select("130-136")
