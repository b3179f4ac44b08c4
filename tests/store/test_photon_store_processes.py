"""The photon store under real processes: concurrent writers, and a writer killed mid-write."""
from __future__ import annotations

import multiprocessing
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from photonstore_helpers import IDENTITY, contents, make_batch, write_frame, write_frame_task

from pipeline.store import PhotonStore, sort_records

N_ELEMENTS = 2000
HELPERS = str(Path(__file__).parent)


def create(path: Path, n_frames: int) -> str:
    PhotonStore.create(path, n_frames=n_frames, n_elements=N_ELEMENTS,
                       frame_numbers=list(range(n_frames)), max_batches=9, **IDENTITY)
    return str(path)


def assert_batch_intact(store: PhotonStore, frame: int, batch: int, start: int, n: int) -> int:
    """A done batch holds exactly the records it was given; returns its photons emitted."""
    expect = make_batch(frame, batch, n, N_ELEMENTS, photon_start=start)
    got = store.read_frame(frame, batches=[batch])
    order = sort_records(expect.key, expect.bary, expect.energy)
    np.testing.assert_array_equal(got.key, expect.key[order])
    np.testing.assert_array_equal(got.energy, expect.energy[order])
    np.testing.assert_array_equal(np.stack([got.b1, got.b2], 1), expect.bary[order])
    assert got.photons_emitted == expect.photons_emitted
    return expect.photons_emitted


def test01_concurrent_writers_in_processes(tmp_path):
    """Three spawned processes write six frames into the shared tables at once, each task twice
    (as a Dask retry of a presumed-dead worker would): batch 0 of every frame, then batch 1."""
    plan = {f: [3000 + 500 * f, 4000] for f in range(6)}
    shared = create(tmp_path / "shared.zarr", 6)
    serial = create(tmp_path / "serial.zarr", 6)
    pids = set()
    with multiprocessing.get_context("spawn").Pool(3) as pool:
        for b in (0, 1):
            tasks = [(shared, f, sizes, N_ELEMENTS, [b]) for f, sizes in plan.items()] * 2
            pids.update(pool.map(write_frame_task, tasks[::1 - 2 * b], chunksize=1))
    assert len(pids) > 1
    store = PhotonStore.open(shared, **IDENTITY)
    for f, sizes in plan.items():
        assert store.done_batches(f) == [0, 1]
        start = 0
        for b, n in enumerate(sizes):
            start += assert_batch_intact(store, f, b, start, n)
        write_frame(serial, f, sizes, N_ELEMENTS)
    # Same bytes as one process writing everything in order: scheduling leaves no trace
    assert contents(tmp_path / "shared.zarr") == contents(tmp_path / "serial.zarr")


WRITER = textwrap.dedent("""
    import sys
    sys.path.insert(0, {helpers!r})
    from photonstore_helpers import IDENTITY, make_batch
    from pipeline.store import PhotonStore
    store = PhotonStore.open({url!r}, mode="r+", **IDENTITY)
    start = 0
    for b, n in enumerate({sizes!r}):
        batch = make_batch(0, b, n, {n_elements}, photon_start=start)
        store.write_batch(0, b, batch)
        start += batch.photons_emitted
        print("done", b, flush=True)
""")


@pytest.mark.parametrize("delay", [0.0, 0.05, 0.2])
def test02_writer_killed_mid_write(tmp_path, delay):
    """SIGKILL a writer: done batches are intact, the rest not done, and a rerun ends identical."""
    # Doubling batches up to 2.56 M records: several seconds of writing, so the kill lands mid-run
    sizes = [20_000, 20_000, 40_000, 80_000, 160_000, 320_000, 640_000, 1_280_000, 2_560_000]
    url = create(tmp_path / "killed.zarr", 1)
    code = WRITER.format(helpers=HELPERS, url=url, sizes=sizes, n_elements=N_ELEMENTS)
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().split() == ["done", "0"]
        time.sleep(delay)
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait(timeout=60)
        proc.stdout.close()
    assert proc.returncode == -signal.SIGKILL, "writer finished before it was killed"

    store = PhotonStore.open(url, **IDENTITY)
    done = store.done_batches(0)
    assert done == list(range(len(done))) and 1 <= len(done) < len(sizes)
    start = 0
    for b in done:
        start += assert_batch_intact(store, 0, b, start, sizes[b])
        assert store.verify_batch(0, b)
    assert store.photons_emitted(0) == start

    # Resume: done batches are skipped, the interrupted one is rewritten in place
    write_frame(url, 0, sizes, N_ELEMENTS)
    clean = create(tmp_path / "clean.zarr", 1)
    write_frame(clean, 0, sizes, N_ELEMENTS)
    assert contents(tmp_path / "killed.zarr") == contents(tmp_path / "clean.zarr")
