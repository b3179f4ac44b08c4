"""The photon hit record: its 20-byte layout, validation, total order and per-element tables.

Pure NumPy, no zarr: what a batch of records must satisfy before the store writes it.
"""
from __future__ import annotations

import hashlib
import threading
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from kernels.record_layout import BARY_SCALE, DIRECT_BIT, ELEMENT_BITS, ELEMENT_MASK, PARITY_BIT  # noqa: F401

from ..errors import LoomError

FIELDS = (("key", np.uint32, 1), ("bary", np.uint16, 2), ("energy", np.float32, 3))
RECORD_BYTES = 20
assert sum(np.dtype(t).itemsize * k for _, t, k in FIELDS) == RECORD_BYTES, "record is 20 bytes"
CATEGORIES = ("indirect_even", "indirect_odd", "direct_even", "direct_odd")  # key >> ELEMENT_BITS


def pack_key(element: npt.ArrayLike, photon_index: npt.ArrayLike, direct: npt.ArrayLike) -> np.ndarray:
    """u32 keys from element ids, photon indices (only their parity is kept) and direct flags."""
    element = np.asarray(element)
    if element.size and (element.min() < 0 or element.max() > ELEMENT_MASK):
        raise ValueError(f"element ids must be in [0, {ELEMENT_MASK}]")  # a caller's bug, not the user's
    parity = (np.asarray(photon_index) & 1).astype(np.uint32)
    return (element.astype(np.uint32) | parity << np.uint32(ELEMENT_BITS)
            | np.asarray(direct, dtype=bool).astype(np.uint32) << np.uint32(ELEMENT_BITS + 1))


def records_digest(rows: np.ndarray, *extra: int) -> int:
    """64-bit fingerprint of a batch: the first 8 bytes (little-endian) of SHA-256 over its packed
    on-disk rows (:func:`pack_records`, u32 little-endian, row-major) and the ``extra`` integers
    (int64). SHA-256 runs in hardware on current x86 (SHA-NI) and ARM cores: 2x faster than the
    BLAKE2b of format 1-2, and the packed rows are hashed in place, not copied field by field."""
    h = hashlib.sha256(np.ascontiguousarray(rows, "<u4"))
    h.update(np.array(extra, "<i8").tobytes())
    return int.from_bytes(h.digest()[:8], "little")


def parts_digest(parts: Iterable[np.ndarray], *extra: int) -> int:
    """:func:`records_digest` of arrays one after the other (their little-endian bytes, no
    joined copy) and the ``extra`` integers: the digest of a batch stored without records (its
    summary words and hit counts, pipeline/store/photon_store.py)."""
    h = hashlib.sha256()
    for part in parts:
        h.update(np.ascontiguousarray(part, np.asarray(part).dtype.newbyteorder("<")))
    h.update(np.array(extra, "<i8").tobytes())
    return int.from_bytes(h.digest()[:8], "little")


@dataclass(frozen=True)
class FrameRecords:
    """One frame's records merged over batches: element-major, batch order within an element."""

    frame_index: int
    source_frame: int  # frame whose photons these are (== frame_index unless shared)
    batches: tuple[int, ...]
    key: np.ndarray  # u32 (n,)
    element: np.ndarray  # u32 (n,)
    direct: np.ndarray  # bool (n,)
    parity: np.ndarray  # u8 (n,), 1 = odd photon index
    b1: np.ndarray  # u16 (n,), /65535
    b2: np.ndarray  # u16 (n,)
    energy: np.ndarray  # f32 (n, 3)
    offsets: np.ndarray  # i64 (n_elements + 1,): element e is [offsets[e], offsets[e + 1])
    photons_emitted: int
    dropped: int = 0  # damaged records left out on reading (valid_records)

    def __len__(self) -> int:
        return int(self.key.shape[0])

    @classmethod
    def merge(cls, frame_index: int, source_frame: int, batches: Iterable[int],
              parts: Iterable[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]], n_elements: int,
              photons_emitted: int, dropped: int = 0) -> FrameRecords:
        """Merge element-sorted batches ``parts`` [(key, bary, energy, offsets)] in batch order:
        element-major, and within an element batch 0's records first (what a stable sort by
        element of the concatenation gives, computed from the offsets in O(n))."""
        parts = list(parts)
        offsets = sum((np.asarray(p[3], np.int64) for p in parts), np.zeros(n_elements + 1, np.int64))
        if len(parts) == 1:
            key, bary, energy = (np.ascontiguousarray(a) for a in parts[0][:3])
        else:
            n = int(offsets[-1])
            key = np.empty(n, np.uint32)
            bary = np.empty((n, 2), np.uint16)
            energy = np.empty((n, 3), np.float32)
            before = np.zeros(n_elements, np.int64)  # records of earlier batches per element
            for k, b, e, o in parts:
                o = np.asarray(o, np.int64)
                count = np.diff(o)
                shift = offsets[:-1] + before - o[:-1]  # destination - source index, per element
                dest = np.arange(o[-1], dtype=np.int64) + np.repeat(shift, count)
                key[dest], bary[dest], energy[dest] = k, b, e
                before += count
        element = key & np.uint32(ELEMENT_MASK)
        return cls(frame_index, source_frame, tuple(batches), key, element,
                   (key & DIRECT_BIT) != 0, ((key & PARITY_BIT) != 0).astype(np.uint8),
                   bary[:, 0].copy(), bary[:, 1].copy(), energy, offsets, photons_emitted, dropped)


@dataclass(frozen=True)
class SortedBatch:
    """A validated batch in the store's total order: its packed on-disk rows (:func:`pack_records`)
    and per-element tables."""

    rows: np.ndarray  # u32 (5, n)
    offsets: np.ndarray  # i64 (n_elements + 1,)
    counts: np.ndarray  # u64 (4, n_elements), this batch only, rows in CATEGORIES order

    def __len__(self) -> int:
        return int(self.rows.shape[1])

    @property
    def key(self) -> np.ndarray:
        return self.rows[0]

    def digest(self, *extra: int) -> int:
        return records_digest(self.rows, *extra)

    def packed(self) -> np.ndarray:
        """u32 (5, n): the on-disk rows (:func:`pack_records`)."""
        return self.rows


def pack_records(key: np.ndarray, bary: np.ndarray, energy: np.ndarray) -> np.ndarray:
    """u32 (5, n) rows key, b1 | b2 << 16, and the bits of energy R, G, B: the record fields as
    one struct-of-arrays block (pipeline.store, FORMAT_VERSION 2)."""
    n = key.shape[0]
    out = np.empty((5, n), np.uint32)
    out[0] = key
    out[1] = bary[:, 0]
    out[1] |= bary[:, 1].astype(np.uint32) << np.uint32(16)
    out[2:5] = np.ascontiguousarray(energy, np.float32).view(np.uint32).T
    return out


# Energy bits of a finite float32 >= 0 lie below those of +Inf (sign bit clear, exponent not all ones)
_INF_BITS = np.uint32(0x7F800000)


def valid_records(rows: np.ndarray, n_elements: int) -> tuple[np.ndarray, int]:
    """(rows, dropped): the packed rows (:func:`pack_records`) without records that no tracer
    writes (the store refuses them): a NaN, infinite or negative energy, or an element id the
    mesh does not have. They come from damage or a foreign writer, and one NaN would spread
    through every window sum and filter ring of its element into frames. Checked on the bits:
    one u32 comparison a value, nothing copied when every record is valid."""
    if not rows.shape[1] or (rows[2:5].max() < _INF_BITS
                             and int((rows[0] & np.uint32(ELEMENT_MASK)).max()) < n_elements):
        return rows, 0
    ok = (rows[2:5] < _INF_BITS).all(axis=0) & ((rows[0] & np.uint32(ELEMENT_MASK)) < n_elements)
    return np.ascontiguousarray(rows[:, ok]), int(rows.shape[1] - np.count_nonzero(ok))


def unpack_records(rows: np.ndarray, n_elements: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(key, bary, energy, offsets) of a (5, n) block written by :func:`pack_records`."""
    key = np.ascontiguousarray(rows[0])
    # Row 1 is b1 | b2 << 16 in little-endian u32: as u16 pairs it is (b1, b2) already
    bary = np.ascontiguousarray(rows[1]).astype("<u4", copy=False).view("<u2").reshape(-1, 2)
    energy = np.ascontiguousarray(rows[2:5].T).view(np.float32)
    offsets = np.zeros(n_elements + 1, np.int64)
    np.cumsum(np.bincount(key & np.uint32(ELEMENT_MASK), minlength=n_elements), out=offsets[1:])
    return key, bary, energy, offsets


def as_int(value: object, name: str, where: str, lo: int, hi: int | None = None) -> int:
    """``value`` as an int in [lo, hi), or a one-line LoomError."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise LoomError(f"{name} must be an integer, got {value!r}", path=where)
    value = int(value)
    if value < lo or (hi is not None and value >= hi):
        bound = f"in [{lo}, {hi})" if hi is not None else f">= {lo}"
        raise LoomError(f"{name} {value} is out of range (must be {bound})", path=where)
    return value


def as_array(value: npt.ArrayLike, name: str, shape_tail: tuple[int, ...], dtype: npt.DTypeLike,
             where: str) -> np.ndarray:
    """Check shape and convert to ``dtype`` without wrapping, rounding or NaN."""
    arr = np.asarray(value)
    if arr.ndim != 1 + len(shape_tail) or arr.shape[1:] != shape_tail:
        want = "(n" + "".join(f", {k}" for k in shape_tail) + ")"
        raise LoomError(f"{name} has shape {arr.shape}, expected {want}", path=where)
    if np.dtype(dtype).kind == "u":
        if arr.dtype.kind not in "ui" and arr.size:
            raise LoomError(f"{name} must be integers, got {arr.dtype}", path=where)
        if arr.size and not np.can_cast(arr.dtype, dtype) and (arr.min() < 0 or arr.max() > np.iinfo(dtype).max):
            raise LoomError(f"{name} has values outside {np.dtype(dtype).name}", path=where)
    elif arr.size and (arr.dtype.kind not in "fiu" or not np.isfinite(arr).all()
                       or (arr < 0).any()):
        raise LoomError(f"{name} must be finite and >= 0", path=where)
    return np.ascontiguousarray(arr, dtype=dtype)


def sort_records(key: np.ndarray, bary: np.ndarray, energy: np.ndarray) -> np.ndarray:
    """Permutation into the total order (element, key, b1, b2, energy bits): input-order free.
    Slow twin: :func:`sort_records_reference`.

    A least-significant-digit radix sort over 16-bit digits: numpy's stable argsort of u16 values
    is a counting sort, O(n) a pass, so (b2, b1, then the group's 16-bit digits) take 3 passes on
    ROOM, and the energy bits 6 more only where (element, category, b1, b2) repeat. A ROOM batch of
    134,000 records: 2.4 against 12.6 ms for the two packed u64 sorts this replaced (docs/04-photons.md
    §3)."""
    key = np.asarray(key, np.uint32)
    n = key.shape[0]
    if n == 0:
        return np.empty(0, np.int64)
    # element << 2 | category is key rotated left by 2: the order's leading part in one u32
    group = (key << np.uint32(2)) | (key >> np.uint32(ELEMENT_BITS))
    b = np.ascontiguousarray(bary, "<u2")
    digits = [b[:, 1], b[:, 0]] + [(group >> np.uint32(s)).astype(np.uint16)
                                   for s in range(0, max(1, int(group.max()).bit_length()), 16)]
    order = _lsd_order(digits)
    g = np.take(group, order)
    pair = np.take(b.view("<u4").reshape(n), order)
    if ((g[1:] == g[:-1]) & (pair[1:] == pair[:-1])).any():  # ties: the energy bits decide
        bits = np.ascontiguousarray(energy, np.float32).view(np.uint32)
        low_first = [(bits[:, c] >> np.uint32(s)).astype(np.uint16) for c in (2, 1, 0) for s in (0, 16)]
        order = _lsd_order(low_first + digits)
    return order


def _lsd_order(digits: list[np.ndarray]) -> np.ndarray:
    """The stable order of rows keyed by u16 ``digits``, least significant first (equal rows keep
    their input order)."""
    order = np.argsort(digits[0], kind="stable")
    for d in digits[1:]:
        order = np.take(order, np.argsort(np.take(d, order), kind="stable"))
    return order.astype(np.int64, copy=False)


def sort_records_reference(key: np.ndarray, bary: np.ndarray, energy: np.ndarray) -> np.ndarray:
    """The order of :func:`sort_records` by its definition: element, category, b1, b2, then the
    energy bits, then the input index (one lexsort, several times slower)."""
    key = np.asarray(key, np.uint32)
    bary = np.asarray(bary, np.uint16)
    bits = np.ascontiguousarray(energy, np.float32).view(np.uint32)
    return np.lexsort((bits[:, 2], bits[:, 1], bits[:, 0], bary[:, 1], bary[:, 0],
                       key >> np.uint32(ELEMENT_BITS), key & np.uint32(ELEMENT_MASK)))


def check_records(key: npt.ArrayLike, bary: npt.ArrayLike, energy: npt.ArrayLike, n_elements: int,
                  where: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(key, bary, energy) of one batch as u32, u16 and f32 arrays, or a one-line LoomError:
    lengths agree, element ids exist, energies are finite and >= 0 (float32 energies checked on
    their bits, one comparison a value, as :func:`valid_records` does)."""
    key = as_array(key, "key", (), np.uint32, where)
    bary = as_array(bary, "bary", (2,), np.uint16, where)
    energy = np.asarray(energy)
    if energy.dtype == np.float32 and energy.ndim == 2 and energy.shape[1:] == (3,) and (
            not energy.size or energy.view(np.uint32).max() < _INF_BITS):
        energy = np.ascontiguousarray(energy)
    else:
        energy = as_array(energy, "energy", (3,), np.float32, where)
    n = key.shape[0]
    if bary.shape[0] != n or energy.shape[0] != n:
        raise LoomError(f"record arrays differ in length: key {n}, bary {bary.shape[0]}, "
                        f"energy {energy.shape[0]}", path=where)
    if n:  # the element ids in the thread's scratch array (no new memory a batch)
        top = int(np.bitwise_and(key, np.uint32(ELEMENT_MASK), out=scratch("element", n, np.uint32)).max())
        if top >= n_elements:
            raise LoomError(f"element id {top} >= n_elements {n_elements}", path=where)
    return key, bary, energy


def category_counts(key: np.ndarray, n_elements: int) -> np.ndarray:
    """u64 (4, n_elements): hits per category (CATEGORIES order) and element of checked keys;
    order-free. One bincount of element << 2 | category (the key rotated left by 2, sort_records'
    group), made as the intp values bincount takes as they are (it copies anything else into a
    new array) in the thread's scratch arrays."""
    n, size = key.shape[0], len(CATEGORIES) * n_elements
    group, category = scratch("group", n, np.intp), scratch("category", n, np.uint32)
    np.left_shift(key, np.uint32(2), out=category)  # element << 2, the category bits shifted out
    np.copyto(group, category)
    np.right_shift(key, np.uint32(ELEMENT_BITS), out=category)
    np.bitwise_or(group, category, out=group)
    counts = np.bincount(group, minlength=size)[:size]
    return np.ascontiguousarray(counts.reshape(n_elements, len(CATEGORIES)).T, np.uint64)


_SCRATCH = threading.local()


def scratch(name: str, n: int, dtype: npt.DTypeLike) -> np.ndarray:
    """A 1-D array of ``n`` ``dtype`` values (contents undefined) that this thread gets again at
    the next call with ``name``, grown to the next power of two when too small.

    For temporaries of the store's hot paths: an array the size of a batch, new at every call,
    costs a page fault a 4 KiB page, and on the build machines (whose free memory the host
    reclaims, docs/13-cluster.md §5) that is 3-33 us a page, several ms a batch.
    The caller uses the array before its next call with the same name and returns none of it."""
    size = n * np.dtype(dtype).itemsize
    kept = getattr(_SCRATCH, "arrays", None)
    if kept is None:
        kept = _SCRATCH.arrays = {}
    buf = kept.get(name)
    if buf is None or buf.nbytes < size:
        buf = kept[name] = np.empty(1 << max(12, (size - 1).bit_length()), np.uint8)
    return buf[:size].view(dtype)


def element_grouped(key: np.ndarray, bary: np.ndarray, energy: np.ndarray, n_elements: int, *,
                    with_counts: bool = False) -> tuple[np.ndarray, ...]:
    """(key, bary, energy, offsets) grouped by element, each element's records in input order: the
    order a batch's sums are added in (pipeline/collection/batch_sums.py). A counting sort per 16-bit digit of
    the element id (one pass below 65,536 elements), a fraction of the total order's cost; the
    tracer's output order is itself deterministic (pipeline/photons/tracing.py), so the sums are too.
    ``with_counts``: and the :func:`category_counts` of the keys, from the one bincount that gives
    the offsets (per element and category instead of per element)."""
    element = key & np.uint32(ELEMENT_MASK)
    n = key.shape[0]
    top = int(element.max()) if n else 0
    order = _lsd_order([(element >> np.uint32(s)).astype(np.uint16) for s in range(0, max(1, top.bit_length()), 16)]
                       ) if n else np.empty(0, np.int64)
    offsets = np.zeros(n_elements + 1, np.int64)
    counts = category_counts(key, n_elements) if with_counts else None
    np.cumsum(counts.sum(axis=0, dtype=np.int64) if with_counts else np.bincount(element, minlength=n_elements),
              out=offsets[1:])
    grouped = (np.take(key, order), np.take(bary, order, axis=0), np.take(energy, order, axis=0), offsets)
    return (*grouped, counts) if with_counts else grouped


def sorted_batch(key: np.ndarray, bary: np.ndarray, energy: np.ndarray, n_elements: int) -> SortedBatch:
    """Checked arrays (:func:`check_records`) sorted into the total order, packed as on disk, with
    their per-element tables."""
    n = key.shape[0]
    # Sort into the total order, straight into the packed rows, then count per element and category
    order = sort_records(key, bary, energy)
    rows = np.empty((5, n), np.uint32)
    np.take(key, order, out=rows[0])
    # little-endian u16 pairs (b1, b2) read as a little-endian u32 are b1 | b2 << 16
    np.take(np.ascontiguousarray(bary, "<u2").view("<u4").reshape(n), order, out=rows[1])
    bits = energy.view(np.uint32)
    for c in range(3):  # a column at a time: 3x faster than taking rows and transposing them
        np.take(bits[:, c], order, out=rows[2 + c])
    counts = category_counts(rows[0], n_elements)
    offsets = np.zeros(n_elements + 1, dtype=np.int64)
    np.cumsum(counts.sum(axis=0), out=offsets[1:])
    return SortedBatch(rows, offsets, counts)
