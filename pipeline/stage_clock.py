"""Seconds per named stage, added up in a caller's dict (the ``times`` the tasks return)."""
from __future__ import annotations

import time


class StageClock:
    """Adds the seconds since the last lap to ``times[key]`` (nothing when ``times`` is None)."""

    def __init__(self, times: dict | None):
        self.times, self.now = times, time.perf_counter
        self.last = self.now()

    def lap(self, key: str | None) -> None:
        if self.times is None:
            return
        t = self.now()
        if key is not None:
            self.times[key] = self.times.get(key, 0.0) + t - self.last
        self.last = t
