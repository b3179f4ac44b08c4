"""What the machine charges for fresh memory and new files, printed beside a timing benchmark.

On the shared 2-core build machines (Firecracker VMs, ext4 root) two costs move by up to 10x
between runs of the same bits and set Table 2's I/O row (docs/13-cluster.md §7):

* the first touch of memory the VM has not backed yet: 3.7 to 33 us a 4 KiB page,
  where a page the guest recycles costs about 0.3 us;
* a new file written on the root ext4: 1.5 MB in 11 to 16 ms on slow stretches, 0.6 to 1.3 ms on
  tmpfs (/dev/shm) in the same minutes. CPU time, not waiting: the store's batch writes took as
  much thread CPU time as wall time.

A run that prints them can tell a slow machine from a slower program.
"""
from __future__ import annotations

import mmap
import os
import time
from pathlib import Path
from typing import Callable

PAGE = mmap.PAGESIZE
FILE_BYTES = 1_500_000  # about a ROOM batch's records at 40,000 photons (1.9 MB) or its summary (0.8 MB)


def first_touch_us(megabytes: int = 64) -> float:
    """Microseconds to touch one fresh page of an anonymous mapping of ``megabytes``."""
    if megabytes <= 0:
        raise ValueError(f"megabytes must be positive, got {megabytes}")
    n = megabytes << 20
    with mmap.mmap(-1, n) as m:
        t = time.perf_counter()
        for i in range(0, n, PAGE):
            m[i] = 1
        return (time.perf_counter() - t) / (n // PAGE) * 1e6


def new_file_ms(directory: str | os.PathLike[str], size: int = FILE_BYTES, count: int = 8) -> float:
    """Milliseconds to write one new file of ``size`` bytes in ``directory`` under a temporary name
    and rename it into place, as the photon store writes a batch's records (the median of
    ``count``); the files are removed."""
    if size <= 0 or count <= 0:
        raise ValueError(f"size and count must be positive, got {size} and {count}")
    data = os.urandom(size)
    base = Path(directory)
    times, made = [], []
    try:
        for i in range(count):
            tmp, path = base / f".loom-machine-{os.getpid()}-{i}.partial", base / f".loom-machine-{os.getpid()}-{i}"
            made += [tmp, path]
            t = time.perf_counter()
            with open(tmp, "wb") as fh:
                fh.write(data)
            os.replace(tmp, path)
            times.append(time.perf_counter() - t)
    finally:  # also a temporary file a failed write left
        for path in made:
            path.unlink(missing_ok=True)
    times.sort()
    return times[len(times) // 2] * 1e3


def machine_costs(directory: str | os.PathLike[str]) -> dict:
    """Both costs now: {"new_file_ms": ..., "first_touch_us": ...} (the file in ``directory``)."""
    return {"new_file_ms": new_file_ms(directory), "first_touch_us": first_touch_us()}


def describe(costs: dict) -> str:
    return (f"a new {FILE_BYTES / 1e6:g} MB file {costs['new_file_ms']:.1f} ms, fresh memory "
            f"{costs['first_touch_us']:.1f} us a page")


def announce(directory: str | os.PathLike[str], when: str, echo: Callable[[str], None]) -> dict:
    """:func:`machine_costs` now, printed as ``machine WHEN: ...`` (a benchmark's before and after)."""
    costs = machine_costs(directory)
    echo(f"machine {when}: {describe(costs)}")
    return costs
