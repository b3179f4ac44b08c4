"""Frame numbering and render-farm frame ranges.

Frames are numbered from 1, as render farms number them; frame ``f`` shows the scene at
``t = (f - 1) / fps`` seconds (docs/03-conventions.md §4), so
frame 1 is the animation's first key. A scene with ``frames`` frames spans (frames - 1) / fps
seconds. Range syntax (Nuke, Deadline, OpenCue): ``1-100``, ``1-100x2`` (step 2), ``1,5,10-20``.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

from ..errors import LoomError

DEFAULT_FPS = 30.0
# Frames a timeline (and so a render or a frame range) may have: 55 minutes at 30 fps, far beyond
# one render job, and small enough that planning, loading and `loom info` stay in seconds and in
# megabytes (docs/14-robustness.md §1).
MAX_FRAMES = 100_000
_PART = re.compile(r"^\s*(-?\d+)\s*(?:-\s*(-?\d+)\s*(?:x\s*(\d+)\s*)?)?$")


@dataclass(frozen=True)
class Timeline:
    fps: float
    frames: int  # frames are 1..frames, at most MAX_FRAMES

    def __post_init__(self) -> None:
        if not 1 <= self.frames <= MAX_FRAMES:
            raise LoomError(f"{self.frames} frames: a timeline has 1 to {MAX_FRAMES:,}", field="frames")

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame."""
        return (self.frames - 1) / self.fps

    @property
    def first(self) -> int:
        return 1

    @property
    def last(self) -> int:
        return self.frames

    def time(self, frame: int) -> float:
        return (frame - 1) / self.fps

    def all_frames(self) -> list[int]:
        return list(range(1, self.frames + 1))

    def select(self, spec: str | None) -> list[int]:
        """Frames named by a farm range string, checked against the timeline; ``None`` means all."""
        if spec is None or spec.strip() in ("", "all"):
            return self.all_frames()
        return parse_frame_range(spec, bounds=(self.first, self.last))


def parse_frame_range(spec: str, bounds: tuple[int, int] | None = None) -> list[int]:
    """Parse ``1-100``, ``1-100x2``, ``1,5,10-20`` into a sorted list of unique frame numbers.

    Every part is checked against ``bounds`` (the timeline's first and last frame) and the count
    against :data:`MAX_FRAMES` before a single frame is listed, so ``1-1000000000`` is a one-line
    error, not a billion-element set."""
    parts = []
    total = 0
    for part in spec.split(","):
        m = _PART.match(part)
        if not m:
            raise LoomError(f"cannot parse {part.strip()!r} in {spec!r} (use 1-100, 1-100x2, 1,5,10-20)",
                            field="frames")
        start = int(m.group(1))
        end = int(m.group(2)) if m.group(2) is not None else start
        step = int(m.group(3)) if m.group(3) is not None else 1
        if step < 1:
            raise LoomError(f"step must be >= 1 in {part.strip()!r}", field="frames")
        if end < start:
            raise LoomError(f"range {part.strip()!r} ends before it starts", field="frames")
        if bounds is not None:
            for f in (start, end):
                if not bounds[0] <= f <= bounds[1]:
                    raise LoomError(f"frame {f} is outside the timeline {bounds[0]}-{bounds[1]}", field="frames")
        total += (end - start) // step + 1
        if total > MAX_FRAMES:
            raise LoomError(f"{spec!r} names more than {MAX_FRAMES:,} frames", field="frames")
        parts.append(range(start, end + 1, step))
    return sorted(set().union(*parts))
