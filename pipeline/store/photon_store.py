"""The photon store: every photon hit of a run, on zarr v3, written once per (frame, batch).

Photons are the only state of a run that costs tracing; everything downstream (temporal windows,
illumination maps, frames) is recomputed from them and the config (DESIGN.md, "The photon store").

Record (dept.md §1.1), exactly ``RECORD_BYTES`` = 20 bytes uncompressed, stored struct-of-arrays::

    key     u32     bits 0-29 element id, bit 30 photon-index parity (1 = odd), bit 31 direct
    bary    2 x u16 b1, b2 fixed point /65535 (b0 = 1 - b1 - b2)
    energy  3 x f32 RGB energy (throughput x per-photon power, scaled by the tracer)

On disk (``F`` frames, ``B`` = max_batches, ``E`` elements)::

    run.zarr/
      zarr.json          group; attributes: format, format_version, scene_hash, config_hash, seed,
                         n_frames, n_elements, frame_numbers, max_batches, record_layout, complete
      batch/             (F, B, 5) u64, chunk (1, 1, 5), keys "c.f.b.0": [DONE_MAGIC, photon_start,
                         photons_emitted, n_records, digest]; a chunk exists <=> the batch is done
      counts/            (F, B, 4, E) u32, chunk (1, 1, 4, E): hits of batches 0..b (running sum)
                         per category indirect-even, indirect-odd, direct-even, direct-odd
      source/            (F,) i32, one chunk, -1 or the frame whose photons frame f reuses
      frames/<f>/        group per frame, made by the coordinator
        <b>/             made by the writer of (f, b) and by nobody else
          key (n,) u32   bary (n, 2) u16   energy (n, 3) f32   records sorted by element
          offsets (E+1,) i64   records of element e are [offsets[e], offsets[e+1])

Why this layout. Record counts per batch are unknown until traced and vary 2x per doubling
(§5.2.3), so each batch gets its own exactly-sized arrays, created by its writer under
``frames/<f>/<b>/``: in zarr v3 that writes only metadata inside the batch's own prefix
(parents exist), so no shared metadata and no resize. A preallocated (frame, capacity) layout
would need a capacity guess and coordinator resizes. The small fixed-size tables (batch, counts,
source) are made by the coordinator in :meth:`PhotonStore.create`; a chunk of them belongs to
exactly one (frame, batch), so concurrent writers never share a chunk (zarr 3 has no locks).
Counts are running sums so the frames x elements table is one chunk read per frame (300 x 45,000
in well under a second) rather than one per batch.

Atomicity and idempotence. LocalStore writes every chunk as temp file + rename, so a chunk is
whole or absent. A writer writes records, offsets and counts first and the ``batch`` chunk last;
that chunk is the done marker, so a killed writer leaves a batch that is not done, which a rerun
rewrites. Records are sorted into a total order (element, key, b1, b2, energy bits), so the
bytes do not depend on input order, and a rerun writes identical bytes over identical chunks
(existing arrays are reused, never deleted, so a duplicate task cannot expose a done batch with
missing chunks). Writing a batch that is already done only compares digests. Batch b needs batch
b-1 done and starts at its photon end, so done batches are a prefix 0..k-1 and batch b never
changes once written. ``file://`` URLs map to LocalStore for these guarantees; other fsspec URLs
rely on the object store writing each object whole.
"""
from __future__ import annotations

import hashlib
import os
import re
import urllib.parse
import urllib.request
from dataclasses import dataclass

import numpy as np
import zarr
import zarr.errors
from zarr.codecs import BloscCodec
from zarr.core.sync import sync
from zarr.storage import FsspecStore, LocalStore

from .errors import LoomError

FORMAT = "photonloom.photons"
FORMAT_VERSION = 1
ELEMENT_BITS = 30
ELEMENT_MASK = (1 << ELEMENT_BITS) - 1
PARITY_BIT = np.uint32(1 << 30)
DIRECT_BIT = np.uint32(1 << 31)
BARY_SCALE = 65535
FIELDS = (("key", np.uint32, 1), ("bary", np.uint16, 2), ("energy", np.float32, 3))
RECORD_BYTES = 20
assert sum(np.dtype(t).itemsize * k for _, t, k in FIELDS) == RECORD_BYTES, "record is 20 bytes"
CATEGORIES = ("indirect_even", "indirect_odd", "direct_even", "direct_odd")  # (direct << 1) | parity
BATCH_FIELDS = ("done_magic", "photon_start", "photons_emitted", "n_records", "digest")
DONE_MAGIC = 0x4C4F4F4D  # "LOOM": the batch chunk is written last, so its presence means done
RECORD_CHUNK = 1 << 20  # records per chunk of the per-batch arrays (20 MiB raw)
_IDENTITY = ("scene_hash", "config_hash", "seed", "n_frames", "n_elements", "frame_numbers",
             "max_batches")
_BATCH_CHUNK = re.compile(r"c\.(\d+)\.(\d+)\.0")


def _codec() -> BloscCodec:
    # Byte shuffle + zstd: sorted keys and small counts compress well; low level keeps writes fast.
    return BloscCodec(cname="zstd", clevel=3, shuffle="shuffle")


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
    offsets: np.ndarray  # i64 (n_elements + 1,)
    photons_emitted: int

    def __len__(self) -> int:
        return int(self.key.shape[0])


@dataclass(frozen=True)
class _Batch:
    """A validated, sorted batch ready to write; ``row`` is its done marker."""

    frame: int
    batch: int
    key: np.ndarray
    bary: np.ndarray
    energy: np.ndarray
    offsets: np.ndarray
    counts: np.ndarray  # u64 (4, n_elements), this batch only
    row: np.ndarray  # u64 (5,) in BATCH_FIELDS order


def _make_store(url, read_only: bool):
    """LocalStore for paths and file:// URLs (atomic renames), FsspecStore for other URLs."""
    text = os.fspath(url)
    if "://" not in text:
        return LocalStore(text, read_only=read_only)
    if text.startswith("file://"):
        return LocalStore(urllib.request.url2pathname(urllib.parse.urlparse(text).path),
                          read_only=read_only)
    return FsspecStore.from_url(text, read_only=read_only)


def _list_dir(store, prefix: str) -> list[str]:
    async def collect() -> list[str]:
        return [name async for name in store.list_dir(prefix)]
    return sync(collect())


def _open_root(store, where: str, mode: str):
    """The root group, or None if nothing is there; LoomError if something else is."""
    if isinstance(store, LocalStore) and not store.root.exists():
        return None  # checked first: opening a writable LocalStore would make the directory
    try:
        return zarr.open_group(store=store, mode=mode)
    except (zarr.errors.GroupNotFoundError, FileNotFoundError):
        if _list_dir(store, ""):
            raise LoomError("exists and is not a photon store (not a zarr group)", path=where)
        return None
    except zarr.errors.ContainsArrayError:
        raise LoomError("is a zarr array, not a photon store", path=where) from None
    except (ValueError, KeyError, TypeError) as err:
        raise LoomError(f"unreadable zarr metadata ({err})", path=where) from None


def _check_identity(attrs: dict, expected: dict, where: str) -> None:
    if attrs.get("format") != FORMAT:
        raise LoomError("is a zarr group but not a photon store (no format attribute)", path=where)
    if attrs.get("format_version") != FORMAT_VERSION:
        raise LoomError(f"store format version {attrs.get('format_version')!r}, this photonloom "
                        f"reads version {FORMAT_VERSION}", path=where)
    for name, want in expected.items():
        if want is not None and attrs.get(name) != want:
            raise LoomError(f"store was made with {name}={attrs.get(name)!r}, not {want!r}; "
                            "never mixed: use another store path", path=where, field=name)


def _as_int(value, name: str, where: str, lo: int, hi: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise LoomError(f"{name} must be an integer, got {value!r}", path=where)
    value = int(value)
    if value < lo or (hi is not None and value >= hi):
        bound = f"in [{lo}, {hi})" if hi is not None else f">= {lo}"
        raise LoomError(f"{name} {value} is out of range (must be {bound})", path=where)
    return value


def _as_array(value, name: str, shape_tail: tuple, dtype, where: str) -> np.ndarray:
    """Check shape and convert to ``dtype`` without wrapping, rounding or NaN."""
    arr = np.asarray(value)
    if arr.ndim != 1 + len(shape_tail) or arr.shape[1:] != shape_tail:
        want = "(n" + "".join(f", {k}" for k in shape_tail) + ")"
        raise LoomError(f"{name} has shape {arr.shape}, expected {want}", path=where)
    if np.dtype(dtype).kind == "u":
        if arr.dtype.kind not in "ui" and arr.size:
            raise LoomError(f"{name} must be integers, got {arr.dtype}", path=where)
        if arr.size and (arr.min() < 0 or arr.max() > np.iinfo(dtype).max):
            raise LoomError(f"{name} has values outside {np.dtype(dtype).name}", path=where)
    elif arr.size and (arr.dtype.kind not in "fiu" or not np.isfinite(arr).all()
                       or (arr < 0).any()):
        raise LoomError(f"{name} must be finite and >= 0", path=where)
    return np.ascontiguousarray(arr, dtype=dtype)


def sort_records(key: np.ndarray, bary: np.ndarray, energy: np.ndarray) -> np.ndarray:
    """Permutation into the total order (element, key, b1, b2, energy bits): input-order free."""
    element = (key & ELEMENT_MASK).astype(np.uint64)
    primary = ((element << np.uint64(2) | (key >> np.uint32(30)).astype(np.uint64)) << np.uint64(32)
               | bary[:, 0].astype(np.uint64) << np.uint64(16) | bary[:, 1].astype(np.uint64))
    order = np.argsort(primary, kind="stable")
    ranked = primary[order]
    if ranked.size > 1 and (ranked[1:] == ranked[:-1]).any():  # ties: break by energy bits
        bits = energy.view(np.uint32)
        order = np.lexsort((bits[:, 2], bits[:, 1], bits[:, 0], primary))
    return order


def _digest(*parts: np.ndarray) -> int:
    h = hashlib.blake2b(digest_size=8)
    for part in parts:
        h.update(np.ascontiguousarray(part).tobytes())
    return int.from_bytes(h.digest(), "little")


class PhotonStore:
    """A run's photon store. Make it with :meth:`create` (coordinator) or :meth:`open`."""

    def __init__(self, root: zarr.Group, url: str, mode: str):
        self._root, self.url, self.mode = root, url, mode
        attrs = dict(root.attrs)
        self.n_frames: int = attrs["n_frames"]
        self.n_elements: int = attrs["n_elements"]
        self.max_batches: int = attrs["max_batches"]
        self.frame_numbers: list[int] = list(attrs["frame_numbers"])
        self.scene_hash: str = attrs["scene_hash"]
        self.config_hash: str = attrs["config_hash"]
        self.seed: int = attrs["seed"]
        try:
            self._batch, self._counts, self._source = (root[n] for n in ("batch", "counts", "source"))
        except KeyError as err:
            raise LoomError(f"photon store is missing array {err}", path=url) from None

    # --- making and opening ---------------------------------------------------------------
    @classmethod
    def create(cls, url, *, n_frames: int, n_elements: int, frame_numbers, scene_hash: str,
               config_hash: str, seed: int, max_batches: int = 16) -> PhotonStore:
        """Make the group and every fixed-size array; on an existing identical store, open it.

        Only the coordinator calls this. A store made with other identity attributes is refused.
        """
        where = os.fspath(url)
        n_frames = _as_int(n_frames, "n_frames", where, 1)
        n_elements = _as_int(n_elements, "n_elements", where, 1, ELEMENT_MASK + 2)
        max_batches = _as_int(max_batches, "max_batches", where, 1, 1025)
        seed = _as_int(seed, "seed", where, 0)
        frame_numbers = [_as_int(n, "frame number", where, -(1 << 62)) for n in frame_numbers]
        if len(frame_numbers) != n_frames:
            raise LoomError(f"{len(frame_numbers)} frame_numbers for {n_frames} frames", path=where)
        for name, value in (("scene_hash", scene_hash), ("config_hash", config_hash)):
            if not isinstance(value, str) or not value:
                raise LoomError(f"{name} must be a non-empty string", path=where)
        identity = dict(scene_hash=scene_hash, config_hash=config_hash, seed=seed,
                        n_frames=n_frames, n_elements=n_elements, frame_numbers=frame_numbers,
                        max_batches=max_batches)
        try:
            store = _make_store(url, read_only=False)
            root = _open_root(store, where, "r+")
            if root is not None:
                _check_identity(dict(root.attrs), identity, where)
                if root.attrs.get("complete"):
                    return cls(root, where, "r+")
            else:
                root = zarr.create_group(store=store, attributes=dict(
                    format=FORMAT, format_version=FORMAT_VERSION, complete=False, **identity,
                    record_layout=cls._layout_description(), count_categories=list(CATEGORIES),
                    batch_fields=list(BATCH_FIELDS)))
            cls._make_arrays(root, n_frames, n_elements, max_batches)
            root.attrs.update({"complete": True})  # last: writers refuse incomplete stores
        except OSError as err:
            raise LoomError(f"cannot create photon store: {err.strerror or err}", path=where) from None
        return cls(root, where, "r+")

    @staticmethod
    def _layout_description() -> dict:
        return {"record_bytes": RECORD_BYTES,
                "arrays": {name: {"dtype": np.dtype(t).name, "per_record": k} for name, t, k in FIELDS},
                "key": "bits 0-29 element id, bit 30 photon-index parity (1 = odd), "
                       "bit 31 direct (1 = first hit from a light)",
                "bary": f"b1, b2 fixed point /{BARY_SCALE}; b0 = 1 - b1 - b2",
                "energy": "RGB, photon throughput x per-photon power",
                "order": "element, key, b1, b2, energy bits"}

    @staticmethod
    def _make_arrays(root: zarr.Group, n_frames: int, n_elements: int, max_batches: int) -> None:
        common = dict(overwrite=True, compressors=_codec())
        root.create_array("batch", shape=(n_frames, max_batches, len(BATCH_FIELDS)),
                          chunks=(1, 1, len(BATCH_FIELDS)), dtype="uint64", fill_value=0,
                          chunk_key_encoding={"name": "default", "separator": "."}, **common)
        root.create_array("counts", shape=(n_frames, max_batches, len(CATEGORIES), n_elements),
                          chunks=(1, 1, len(CATEGORIES), n_elements), dtype="uint32",
                          fill_value=0, **common)
        root.create_array("source", shape=(n_frames,), chunks=(n_frames,), dtype="int32",
                          fill_value=-1, **common)
        frames = root.require_group("frames")
        for f in range(n_frames):
            frames.require_group(str(f))

    @classmethod
    def open(cls, url, *, scene_hash: str | None = None, config_hash: str | None = None,
             seed: int | None = None, mode: str = "r") -> PhotonStore:
        """Open an existing store, refusing one made with another scene, config or seed."""
        where = os.fspath(url)
        if mode not in ("r", "r+"):
            raise LoomError(f"mode must be 'r' or 'r+', not {mode!r}", path=where)
        try:
            store = _make_store(url, read_only=(mode == "r"))
            root = _open_root(store, where, mode)
        except OSError as err:
            raise LoomError(f"cannot open photon store: {err.strerror or err}", path=where) from None
        if root is None:
            raise LoomError("no photon store here", path=where)
        _check_identity(dict(root.attrs), dict(scene_hash=scene_hash, config_hash=config_hash,
                                               seed=seed), where)
        if not root.attrs.get("complete"):
            raise LoomError("photon store creation was interrupted; run create again", path=where)
        return cls(root, where, mode)

    # --- what is done ---------------------------------------------------------------------
    def _frame(self, frame_index, name: str = "frame_index") -> int:
        return _as_int(frame_index, name, self.url, 0, self.n_frames)

    def _done_table(self) -> np.ndarray:
        """bool (n_frames, max_batches): which batch chunks exist, from one directory listing."""
        done = np.zeros((self.n_frames, self.max_batches), dtype=bool)
        store = self._root.store
        if store.supports_listing:
            for name in _list_dir(store, "batch"):
                m = _BATCH_CHUNK.fullmatch(name)
                if m and int(m[1]) < self.n_frames and int(m[2]) < self.max_batches:
                    done[int(m[1]), int(m[2])] = True
        else:
            done = self._batch[...][..., 0] == DONE_MAGIC
        return done

    def _sources(self) -> np.ndarray:
        src = self._source[...].astype(np.int64)
        return np.where(src < 0, np.arange(self.n_frames), src)

    def source_frame(self, frame_index: int) -> int:
        """The frame whose photons ``frame_index`` uses (itself unless shared)."""
        return int(self._sources()[self._frame(frame_index)])

    def _meta(self, frame: int, batches) -> np.ndarray:
        if not len(batches):
            return np.zeros((0, len(BATCH_FIELDS)), np.uint64)
        rows = self._batch.get_orthogonal_selection((frame, list(batches), slice(None)))
        if rows.size and (rows[:, 0] != DONE_MAGIC).any():
            raise LoomError(f"frame {frame}: corrupt batch table", path=self.url)
        return rows.reshape(-1, len(BATCH_FIELDS))

    def is_done(self, frame_index: int, batch: int) -> bool:
        f = self.source_frame(frame_index)
        b = _as_int(batch, "batch", self.url, 0, self.max_batches)
        return bool(self._batch[f, b, 0] == DONE_MAGIC)

    def done_batches(self, frame_index: int) -> list[int]:
        f = self.source_frame(frame_index)
        return [int(b) for b in np.flatnonzero(self._done_table()[f])]

    def batches_per_frame(self) -> np.ndarray:
        """int (n_frames,): done batches of every frame (of its source frame, if shared)."""
        return self._done_table().sum(axis=1)[self._sources()]

    def photons_emitted(self, frame_index: int) -> int:
        """Photons emitted for a frame, summed over its done batches."""
        f = self.source_frame(frame_index)
        return int(self._meta(f, self.done_batches(f))[:, 2].sum())

    def batch_info(self, frame_index: int, batch: int) -> dict | None:
        """The done marker of a batch as a dict of BATCH_FIELDS, or None if not done."""
        f = self.source_frame(frame_index)
        b = _as_int(batch, "batch", self.url, 0, self.max_batches)
        row = self._batch[f, b]
        return None if row[0] != DONE_MAGIC else dict(zip(BATCH_FIELDS, map(int, row)))

    # --- writing --------------------------------------------------------------------------
    def _writable(self) -> None:
        if self.mode != "r+":
            raise LoomError("photon store is open read-only (mode='r')", path=self.url)

    def write_batch(self, frame_index: int, batch: int, *, key, bary, energy,
                    photons_emitted: int, photon_start: int) -> bool:
        """Sort and write one batch, done marker last. Returns False if it was already done.

        Rerunning a batch rewrites identical bytes; a done batch is only compared by digest and
        a different one is refused (non-deterministic tracer). Batch b needs b-1 done.
        """
        prepared = self._prepare(frame_index, batch, key, bary, energy, photons_emitted,
                                 photon_start)
        done = self.batch_info(prepared.frame, prepared.batch)
        if done is not None:
            if np.array_equal(np.array(list(done.values()), dtype=np.uint64), prepared.row):
                return False
            raise LoomError("is already done with different photons (digest, count or range "
                            "differ): the tracer is not deterministic", path=self.url,
                            field=f"frame {prepared.frame} batch {prepared.batch}")
        self._write_payload(prepared)
        self._mark_done(prepared)
        return True

    def _prepare(self, frame_index, batch, key, bary, energy, photons_emitted,
                 photon_start) -> _Batch:
        """Validate and sort a batch (reads only the previous batch's done marker)."""
        self._writable()
        f, b = self._frame(frame_index), _as_int(batch, "batch", self.url, 0, self.max_batches)
        where = f"{self.url}: frame {f} batch {b}"
        src = int(self._sources()[f])
        if src != f:
            raise LoomError(f"frame {f} shares the photons of frame {src}; write to {src}",
                            path=where)
        key = _as_array(key, "key", (), np.uint32, where)
        bary = _as_array(bary, "bary", (2,), np.uint16, where)
        energy = _as_array(energy, "energy", (3,), np.float32, where)
        n = key.shape[0]
        if bary.shape[0] != n or energy.shape[0] != n:
            raise LoomError(f"record arrays differ in length: key {n}, bary {bary.shape[0]}, "
                            f"energy {energy.shape[0]}", path=where)
        emitted = _as_int(photons_emitted, "photons_emitted", where, 1)
        start = _as_int(photon_start, "photon_start", where, 0)
        expected_start = 0
        if b > 0:
            prev = self.batch_info(f, b - 1)
            if prev is None:
                raise LoomError(f"batch {b - 1} is not done; batches are written in order",
                                path=where)
            expected_start = prev["photon_start"] + prev["photons_emitted"]
        if start != expected_start:
            raise LoomError(f"photon_start {start} is not contiguous: the previous batch ends at "
                            f"{expected_start}", path=where)
        element = key & np.uint32(ELEMENT_MASK)
        if n and int(element.max()) >= self.n_elements:
            raise LoomError(f"element id {int(element.max())} >= n_elements {self.n_elements}",
                            path=where)

        # Sort into the total order, then count per element and category
        order = sort_records(key, bary, energy)
        key, bary, energy, element = key[order], bary[order], energy[order], element[order]
        category = (key >> np.uint32(30)).astype(np.int64)
        counts = np.bincount(category * self.n_elements + element,
                             minlength=len(CATEGORIES) * self.n_elements)
        counts = counts.reshape(len(CATEGORIES), self.n_elements).astype(np.uint64)
        offsets = np.zeros(self.n_elements + 1, dtype=np.int64)
        np.cumsum(counts.sum(axis=0), out=offsets[1:])
        row = np.array([DONE_MAGIC, start, emitted, n,
                        _digest(key, bary, energy, np.array([start, emitted], np.int64))],
                       dtype=np.uint64)
        return _Batch(f, b, key, bary, energy, offsets, counts, row)

    def _batch_array(self, path: str, data: np.ndarray, chunks: tuple) -> None:
        """Write ``data`` as the whole array at ``path``, reusing an identical existing array."""
        try:
            arr = zarr.open_array(store=self._root.store, path=path, mode="r+")
            fits = arr.shape == data.shape and arr.dtype == data.dtype and arr.chunks == chunks
        except (FileNotFoundError, zarr.errors.NodeNotFoundError):
            fits = False
        if not fits:  # first attempt (or a crashed one of another size): make it fresh
            arr = self._root.create_array(path, shape=data.shape, chunks=chunks, dtype=data.dtype,
                                          fill_value=0, compressors=_codec(), overwrite=True)
        arr[...] = data

    def _write_payload(self, p: _Batch) -> None:
        """Records, offsets and running counts of one batch; everything but the done marker."""
        base = f"frames/{p.frame}/{p.batch}"
        rows = max(1, min(p.key.shape[0], RECORD_CHUNK))
        self._batch_array(f"{base}/key", p.key, (rows,))
        self._batch_array(f"{base}/bary", p.bary, (rows, 2))
        self._batch_array(f"{base}/energy", p.energy, (rows, 3))
        self._batch_array(f"{base}/offsets", p.offsets, (p.offsets.shape[0],))
        running = p.counts.copy()
        if p.batch > 0:
            running += self._counts[p.frame, p.batch - 1].astype(np.uint64)
        if running.size and running.max() > np.iinfo(np.uint32).max:
            raise LoomError("per-element hit count overflows u32", path=self.url)
        self._counts[p.frame, p.batch] = running.astype(np.uint32)

    def _mark_done(self, p: _Batch) -> None:
        self._batch[p.frame, p.batch] = p.row  # one chunk, one atomic write: the batch is done

    def share_frame(self, frame_index: int, source_frame_index: int) -> None:
        """Record that frame f reuses frame g's photons (equal scene state); coordinator only."""
        self._writable()
        f, g = self._frame(frame_index), self._frame(source_frame_index, "source_frame_index")
        src = self._source[...]
        where = f"{self.url}: share_frame({f}, {g})"
        if src[f] == g:
            return
        problem = ("a frame cannot share its own photons" if f == g else
                   f"frame {f} already shares frame {src[f]}" if src[f] >= 0 else
                   f"frame {g} itself shares frame {src[g]}; share with {src[g]}" if src[g] >= 0
                   else f"other frames share frame {f}" if (src == f).any() else
                   f"frame {f} already has photons of its own" if self._done_table()[f].any()
                   else None)
        if problem:
            raise LoomError(problem, path=where)
        self._source[f] = g

    # --- reading --------------------------------------------------------------------------
    def read_frame(self, frame_index: int, *, batches=None) -> FrameRecords:
        """All records of a frame's done batches (or of ``batches``), sorted by element."""
        f = self._frame(frame_index)
        g = int(self._sources()[f])
        done = self.done_batches(g)
        if batches is None:
            chosen = done
        else:
            chosen = sorted({_as_int(b, "batch", self.url, 0, self.max_batches) for b in batches})
            missing = [b for b in chosen if b not in done]
            if missing:
                raise LoomError(f"frame {f}: batch(es) {missing} not done", path=self.url)
        meta = self._meta(g, chosen)
        parts = [self._read_batch(g, b, int(row[3])) for b, row in zip(chosen, meta)]
        key = np.concatenate([p[0] for p in parts]) if parts else np.zeros(0, np.uint32)
        bary = np.concatenate([p[1] for p in parts]) if parts else np.zeros((0, 2), np.uint16)
        energy = np.concatenate([p[2] for p in parts]) if parts else np.zeros((0, 3), np.float32)
        offsets = sum((p[3] for p in parts), np.zeros(self.n_elements + 1, np.int64))
        element = key & np.uint32(ELEMENT_MASK)
        order = np.argsort(element, kind="stable")  # each batch is sorted: merge, batch order kept
        key, element, bary, energy = key[order], element[order], bary[order], energy[order]
        return FrameRecords(f, g, tuple(chosen), key, element, (key & DIRECT_BIT) != 0,
                            ((key & PARITY_BIT) != 0).astype(np.uint8), bary[:, 0].copy(),
                            bary[:, 1].copy(), energy, offsets, int(meta[:, 2].sum()))

    def _read_batch(self, f: int, b: int, n: int):
        base = self._root[f"frames/{f}/{b}"]
        arrays = [base[name][...] for name in ("key", "bary", "energy", "offsets")]
        if any(a.shape[0] != n for a in arrays[:3]) or arrays[3][-1] != n:
            raise LoomError(f"frame {f} batch {b}: records do not match its done marker ({n})",
                            path=self.url)
        return arrays

    def counts(self, kind: str = "all", frames=None, parity: int | None = None) -> np.ndarray:
        """u32 (len(frames), n_elements) hit counts over done batches, without reading records.

        ``kind`` is "direct", "indirect" or "all"; ``parity`` 0/1 keeps even/odd photons only.
        """
        if kind not in ("direct", "indirect", "all") or parity not in (None, 0, 1):
            raise LoomError(f"counts(kind={kind!r}, parity={parity!r}): kind must be direct, "
                            "indirect or all and parity None, 0 or 1", path=self.url)
        cats = [c for c in range(len(CATEGORIES))
                if (kind == "all" or (c >> 1) == (kind == "direct"))
                and (parity is None or (c & 1) == parity)]
        chosen = (np.arange(self.n_frames) if frames is None
                  else np.array([self._frame(f, "frame") for f in frames], dtype=np.int64))
        sources = self._sources()[chosen]
        unique, inverse = np.unique(sources, return_inverse=True)
        last = self._done_table()[unique].sum(axis=1) - 1  # done batches are a prefix
        table = np.zeros((unique.shape[0], self.n_elements), dtype=np.uint32)
        block = max(1, (64 << 20) // (4 * len(CATEGORIES) * self.n_elements))
        for b in np.unique(last[last >= 0]):
            rows = np.flatnonzero(last == b)
            # Basic slices over runs of consecutive frames: 4x faster than integer indexing
            runs = np.split(rows, np.flatnonzero(np.diff(unique[rows]) != 1) + 1)
            for run in runs:
                for i in range(0, run.shape[0], block):  # bounded memory: ~64 MiB per read
                    part = run[i:i + block]
                    data = self._counts[int(unique[part[0]]):int(unique[part[-1]]) + 1, int(b)]
                    table[part] = data[:, cats].sum(axis=1, dtype=np.uint32)
        return table[inverse.reshape(-1)]
