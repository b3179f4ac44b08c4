"""Writes past the page cache (pipeline/store/direct_write.py): the same bytes as a plain write,
a clean refusal where the kernel refuses, and the store's record chunks written that way."""
from __future__ import annotations

import ctypes
import mmap
import os

import numpy as np
import pytest

from pipeline.photons.tracing import PhotonBatch
from pipeline.store import PhotonStore, StoreIdentity, direct_write
from pipeline.store.photon_store import _write_object
from pipeline.store.records import sort_records_reference

pytestmark = pytest.mark.skipif(not direct_write.supported(), reason="the platform has no O_DIRECT")


def cached_pages(path) -> int:
    """How many of the file's pages are in the page cache (mincore(2) on a mapping of it)."""
    size = os.path.getsize(path)
    libc = ctypes.CDLL(None, use_errno=True)
    libc.mincore.argtypes = (ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p)
    vec = (ctypes.c_ubyte * -(-size // mmap.PAGESIZE))()
    with open(path, "rb") as fh, mmap.mmap(fh.fileno(), size, access=mmap.ACCESS_COPY) as mm:
        first = ctypes.c_char.from_buffer(mm)  # an export of the mapping: released before it closes
        status = libc.mincore(ctypes.addressof(first), size, vec)
        del first
    if status != 0:
        raise OSError(ctypes.get_errno(), "mincore")
    return sum(v & 1 for v in vec)


def _file_system(path) -> str:
    """The type of the file system holding ``path`` (the longest mount point above it)."""
    best, kind = "", ""
    with open("/proc/mounts") as fh:
        mounts = [line.split()[1:3] for line in fh]
    for mount, fs in mounts:
        if str(path).startswith(mount.rstrip("/") + "/") and len(mount) > len(best):
            best, kind = mount, fs
    return kind


@pytest.mark.parametrize("n", [0, 1, 4095, 4096, 4097, 1_800_001])
def test_direct_write_holds_exactly_the_bytes(tmp_path, n):
    data = np.random.default_rng(n).integers(0, 256, n, dtype=np.uint8).tobytes()
    path = tmp_path / "object"
    assert direct_write.write_new(str(path), data)  # ext4 and tmpfs on Linux >= 6.6 take O_DIRECT
    assert path.read_bytes() == data
    # Over an existing file: truncated, not appended to or left long
    assert direct_write.write_new(str(path), data[: n // 2])
    assert path.read_bytes() == data[: n // 2]


def test_refused_direct_write_leaves_nothing_and_the_object_is_written_plainly(tmp_path, monkeypatch):
    # A length that is no multiple of any block size makes the kernel itself refuse the write (EINVAL)
    monkeypatch.setattr(direct_write, "ALIGN", 100)
    data = bytes(range(256)) * 40
    assert not direct_write.write_new(str(tmp_path / "refused"), data)
    assert list(tmp_path.iterdir()) == []
    _write_object(str(tmp_path / "sub" / "object"), data, direct=True)
    assert (tmp_path / "sub" / "object").read_bytes() == data
    assert [p.name for p in (tmp_path / "sub").iterdir()] == ["object"]  # no *.partial left


def test_store_batches_read_back_the_same_with_and_without_a_summary(tmp_path):
    """Record chunks go past the page cache (a render reads the batch's sums, never its records),
    with or without a summary; both read back exactly as written, and no temporary file stays behind."""
    rng = np.random.default_rng(5)
    n_el = 64
    store = PhotonStore.create(tmp_path / "s.zarr", n_frames=2, n_elements=n_el, frame_numbers=[1, 2],
                               identity=StoreIdentity("s", "c", 0), keep_records=True)
    written = {}
    for f, summarise in ((0, lambda *records: np.arange(7, dtype=np.uint32)), (1, None)):
        n = 5000
        key = (rng.integers(0, n_el, n).astype(np.uint32)
               | (rng.integers(0, 2, n).astype(np.uint32) << np.uint32(30)))
        bary = rng.integers(0, 30000, (n, 2)).astype(np.uint16)
        energy = rng.random((n, 3)).astype(np.float32)
        assert store.write_batch(f, 0, PhotonBatch(key, bary, energy, photons_emitted=2 * n, photon_start=0),
                                 summarise=summarise)
        written[f] = (key, bary, energy)
    # Past the page cache: none of the record pages are cached (on a disk file system; tmpfs
    # keeps every file in memory), while the batch object (counts and sums) written after them is
    chunks = [tmp_path / "s.zarr" / "frames" / f / "0" / "c.0.0" for f in ("0", "1")]
    counts = tmp_path / "s.zarr" / "batch" / "c.1.0"
    assert cached_pages(counts) == -(-os.path.getsize(counts) // mmap.PAGESIZE)
    if _file_system(tmp_path) != "tmpfs":
        assert [cached_pages(c) for c in chunks] == [0, 0]
    assert np.array_equal(store.read_summary(0, 0), np.arange(7))
    assert store.read_summary(1, 0) is None
    reopened = PhotonStore.open(tmp_path / "s.zarr")
    for f, (key, bary, energy) in written.items():
        records = reopened.read_frame(f)
        order = sort_records_reference(key, bary, energy)
        assert np.array_equal(records.key, key[order])
        assert np.array_equal(np.stack([records.b1, records.b2], axis=1), bary[order])
        assert np.array_equal(records.energy, energy[order])
        assert reopened.verify_batch(f, 0)
    assert not list((tmp_path / "s.zarr").rglob("*.partial"))
