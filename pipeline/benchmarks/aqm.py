"""``loom bench aqm``: seconds per 256x256 frame pair of the AQM, without and with pixel flow (NumPy, one core)."""
from __future__ import annotations

import os
import statistics
import time
from typing import TYPE_CHECKING

import click
import numpy as np

from pipeline.aqm import AQM_SIZE, Motion, ViewingConditions, aqm, image_velocity

if TYPE_CHECKING:
    from collections.abc import Callable


def _bench_pair(size: int, seed: int = 0):
    """A 256x256 frame pair with Monte Carlo-like noise and the camera-pan flow of a receding floor."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:size, 0:size] / size
    base = 0.2 + 0.6 * xx * (0.5 + 0.5 * yy) + 0.1 * np.sin(2 * np.pi * 4 * yy)
    a = base * rng.gamma(400, 1 / 400, size=(size, size))
    b = base * rng.gamma(400, 1 / 400, size=(size, size))
    depth = 2.0 + 8.0 * (1.0 - yy)
    cam = np.eye(4)
    moved = np.eye(4)
    moved[0, 3] = -0.05  # camera moves 5 cm to the right per frame
    flow = image_velocity(depth, cam, following=moved, previous=np.linalg.inv(moved), yfov=np.radians(40),
                          fps=25.0, ppd=ViewingConditions().frame_ppd((size, size)))
    return np.repeat(a[..., None], 3, axis=2), np.repeat(b[..., None], 3, axis=2), flow


def run(repeat: int = 10, echo: Callable[[str], None] = click.echo) -> None:
    """Time the AQM on one core (pinned where the OS allows): one cold run, then ``repeat`` timed runs."""
    pinned = hasattr(os, "sched_setaffinity")
    if pinned:  # measure on one core, as the issue asks
        cores = os.sched_getaffinity(0)
        os.sched_setaffinity(0, {min(cores)})
    try:
        _run_bench(repeat, echo)
    finally:
        if pinned:
            os.sched_setaffinity(0, cores)


def _run_bench(repeat: int, echo: Callable[[str], None]) -> None:
    a, b, flow = _bench_pair(AQM_SIZE)
    speed = np.hypot(flow[..., 0], flow[..., 1])
    echo(f"pair: {AQM_SIZE}x{AQM_SIZE}, Monte Carlo-like noise (400 samples), "
         f"flow {speed.min():.1f}..{speed.max():.1f} deg/s")
    for label, kwargs in (("no flow", {}), ("with flow", {"motion": Motion(flow)})):
        start = time.perf_counter()
        d = aqm(a, b, **kwargs).d_aqm
        cold = time.perf_counter() - start
        times = []
        for _ in range(repeat):
            start = time.perf_counter()
            aqm(a, b, **kwargs)
            times.append(time.perf_counter() - start)
        echo(f"aqm numpy {AQM_SIZE}x{AQM_SIZE} {label}: {statistics.median(times):.4f} s/pair median of "
             f"{repeat} (min {min(times):.4f}, cold {cold:.4f}); d_AQM = {d:.2f} %")
