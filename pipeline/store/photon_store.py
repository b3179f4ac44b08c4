"""PhotonStore: the zarr v3 group of a run (layout and guarantees in ``pipeline.store``)."""
from __future__ import annotations

import asyncio
import json
import logging
import os
import re
import struct
import threading
import time
import urllib.parse
import urllib.request
import zlib
from collections import OrderedDict
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple, TypeVar

import numcodecs.blosc
import numpy as np
import numpy.typing as npt
import zarr
import zarr.errors
from zarr.abc.store import RangeByteRequest
from zarr.codecs import BloscCodec
from zarr.core.buffer import default_buffer_prototype
from zarr.core.sync import sync
from zarr.storage import FsspecStore, LocalStore

from ..errors import LoomError
from . import direct_write
from .records import (
    BARY_SCALE,
    CATEGORIES,
    ELEMENT_MASK,
    FIELDS,
    RECORD_BYTES,
    FrameRecords,
    SortedBatch,
    as_int,
    category_counts,
    check_records,
    parts_digest,
    records_digest,
    scratch,
    sorted_batch,
    unpack_records,
    valid_records,
)

if TYPE_CHECKING:
    from pipeline.photons.tracing import PhotonBatch

log = logging.getLogger(__name__)
T = TypeVar("T")
FORMAT = "photonloom.photons"
FORMAT_VERSION = 5  # 5: one object a batch (done marker, running counts, sums); 4: marker, counts and
# sums in three objects; 3: records always, sums optional; 2: BLAKE2b, zstd tables; 1: key/bary/energy/offsets
BATCH_FIELDS = ("photon_start", "photons_emitted", "n_records", "digest")  # batch_info, the header's core
BATCH_MAGIC = b"LOOMBAT5"  # first bytes of a batch object (batch/c.f.b), the done marker
# A batch object's header: the magic, then u64 each: frame, batch, BATCH_FIELDS, the counts' bytes
# and CRC-32, the summary's word count (NO_SUMMARY: none), bytes and CRC-32, and last the CRC-32 of
# everything before it. Then the running counts and the summary words, each lz4 + shuffle.
_HEADER = struct.Struct("<8s12Q")
HEAD = _HEADER.size  # 104 bytes
NO_SUMMARY = (1 << 64) - 1
RECORD_CHUNK = 1 << 20  # records per chunk of the per-batch arrays (20 MiB raw)
RECORD_CACHE_BYTES = 192 << 20  # decoded frames an open_shared instance keeps (LRU, read-only)
RUNNING_CACHE_BYTES = 64 << 20  # running counts a writer keeps of the batches it wrote (LRU)
LISTING_MARGIN_NS = 100_000_000  # a done-table listing is reused once the directory is 0.1 s old
# Chunk keys with "." (c.f.b.0): all chunks of an array in its one directory. A new directory
# costs about 1 ms on ext4 (a block and a journal entry) against 0.1 ms for a new file, and "/" keys
# made five new directories per batch and four per frame of maps.
FLAT_KEYS = {"name": "default", "separator": "."}
_BATCH_OBJECT = re.compile(r"c\.(\d+)\.(\d+)")  # names of batch/ objects


def records_codec() -> BloscCodec:
    # Byte shuffle + zstd: sorted keys and small counts compress well; low level keeps writes fast.
    return BloscCodec(cname="zstd", clevel=3, shuffle="shuffle")


# The per-batch record arrays: byte shuffle + lz4, 4x faster to write and 5x faster to read than
# zstd-3 for 15 % more bytes (ROOM: 14.2 against 12.4 bytes a record); every batch is read about
# three times (the windows of three reconstruction tasks reach it), so decoding speed matters.
BATCH_CODEC = {"cname": "lz4", "clevel": 5, "shuffle": "shuffle", "typesize": 4, "blocksize": 0}


_GROUP_METADATA = json.dumps({"attributes": {}, "zarr_format": 3, "node_type": "group"}, indent=2).encode()


def _batch_metadata(n: int, rows: int) -> bytes:
    """zarr.json of a batch's (5, n) u32 array: what zarr 3 writes for it, written by us."""
    return json.dumps({
        "shape": [5, n], "data_type": "uint32",
        "chunk_grid": {"name": "regular", "configuration": {"chunk_shape": [5, rows]}},
        "chunk_key_encoding": {"name": "default", "configuration": {"separator": "."}},
        "fill_value": 0,
        "codecs": [{"name": "bytes", "configuration": {"endian": "little"}},
                   {"name": "blosc", "configuration": BATCH_CODEC}],
        "attributes": {}, "zarr_format": 3, "node_type": "array", "storage_transformers": []},
        indent=2).encode()


def table_codec() -> BloscCodec:
    """The codec of the illumination maps, whose chunks the store encodes itself
    (:func:`_encode_rows`, as it does a batch object's counts and summary): BATCH_CODEC's lz4 +
    byte shuffle on 4-byte values."""
    return BloscCodec(**BATCH_CODEC)


class _Header(NamedTuple):
    """A batch object's header (:data:`_HEADER`) past its magic, frame and batch."""

    photon_start: int
    photons_emitted: int
    n_records: int
    digest: int
    counts_bytes: int
    counts_crc: int
    n_words: int  # NO_SUMMARY: the batch has none (a store that keeps records, written without)
    words_bytes: int
    words_crc: int

    def pack(self, frame: int, batch: int) -> bytes:
        head = _HEADER.pack(BATCH_MAGIC, frame, batch, *self, 0)[:-8]
        return head + struct.pack("<Q", zlib.crc32(head))

    @classmethod
    def parse(cls, data: bytes | None, frame: int, batch: int) -> _Header | None:
        """The header at the start of ``data`` if it is whole (magic, its CRC) and names (frame,
        batch); else None: the object is no done marker of this batch."""
        if data is None or len(data) < HEAD:
            return None
        magic, f, b, *fields, crc = _HEADER.unpack_from(data)
        if magic != BATCH_MAGIC or crc != zlib.crc32(data[:HEAD - 8]) or (f, b) != (frame, batch):
            return None
        return cls(*fields)


def _encode_rows(block: np.ndarray) -> bytes:
    """A chunk of 4-byte values (u32 or f32) as zarr's BloscCodec(**BATCH_CODEC) encodes it."""
    block = np.ascontiguousarray(block, block.dtype.newbyteorder("<"))
    return numcodecs.blosc.compress(block, BATCH_CODEC["cname"].encode(), BATCH_CODEC["clevel"],
                                    numcodecs.blosc.SHUFFLE, 0, 4)


def _decode(data: bytes, dtype, count: int) -> np.ndarray:
    out = np.frombuffer(numcodecs.blosc.decompress(data), dtype=dtype)
    if out.shape[0] != count:
        raise ValueError(f"chunk holds {out.shape[0]} values, expected {count}")
    return out


_IO = threading.local()  # this thread's byte counts while inside counting_io()


@contextmanager
def counting_io() -> Iterator[dict[str, int]]:
    """Bytes this thread reads and writes through photon stores and illumination maps (their
    objects, as stored) inside the block, as ``{"read_bytes", "write_bytes"}``: what a task
    reports as its I/O. Dask runs tasks in threads, so the count is per thread; nested blocks
    add to the outer one."""
    outer = getattr(_IO, "counts", None)
    _IO.counts = mine = {"read_bytes": 0, "write_bytes": 0}
    try:
        yield mine
    finally:
        _IO.counts = outer
        if outer is not None:
            for k, v in mine.items():
                outer[k] += v


def _counted(kind: str, n: int) -> None:
    counts = getattr(_IO, "counts", None)
    if counts is not None:
        counts[kind] += n


class _Raw:
    """Whole-object reads and writes under the store root, bypassing zarr's array machinery for
    the store's own hot paths (about 1 ms of zarr per call against tens of microseconds). On a
    LocalStore: plain files, written as temp file + rename (atomic, like LocalStore's own
    writes); on other stores one event-loop round trip for a whole list of keys."""

    def __init__(self, store):
        self.store = store
        self.root = store.root if isinstance(store, LocalStore) else None

    def get_many(self, keys: list[str], spans: list[tuple[int, int]] | None = None) -> list[bytes | None]:
        """The objects at ``keys`` (None where absent), or of each only ``spans[i]`` = (offset,
        length) bytes (fewer where the object is shorter)."""
        spans = spans or [None] * len(keys)
        if self.root is not None:
            out = []
            for key, span in zip(keys, spans):
                try:
                    with open(os.path.join(self.root, key), "rb") as fh:
                        if span is None:
                            out.append(fh.read())
                        else:
                            fh.seek(span[0])
                            out.append(fh.read(span[1]))
                except (FileNotFoundError, NotADirectoryError):
                    out.append(None)
            _counted("read_bytes", sum(len(d) for d in out if d is not None))
            return out

        async def fetch():
            got = await asyncio.gather(*(self.store.get(
                k, prototype=default_buffer_prototype(),
                byte_range=None if s is None else RangeByteRequest(s[0], s[0] + s[1])) for k, s in zip(keys, spans)))
            return [None if g is None else g.to_bytes() for g in got]
        out = sync(fetch())
        _counted("read_bytes", sum(len(d) for d in out if d is not None))
        return out

    def get_into(self, key: str, offset: int, out: np.ndarray) -> np.ndarray | bytes | None:
        """``out.nbytes`` bytes of the object at ``key`` from ``offset``: on a LocalStore read into
        ``out`` (the part of it read returned; no new memory), elsewhere as new bytes; None where
        the object is absent."""
        if self.root is None:
            return self.get_many([key], [(offset, out.nbytes)])[0]
        try:
            with open(os.path.join(self.root, key), "rb", buffering=0) as fh:
                fh.seek(offset)
                view, n = memoryview(out).cast("B"), 0
                while n < len(view) and (got := fh.readinto(view[n:])):
                    n += got
        except (FileNotFoundError, NotADirectoryError):
            return None
        _counted("read_bytes", n)
        return out.reshape(-1).view(np.uint8)[:n]

    def set_many(self, items: list[tuple[str, bytes | tuple[bytes, ...]]], *, write_once: Iterable[str] = ()) -> None:
        """Write every (key, bytes), the bytes given whole or as a tuple of parts written one after
        the other (no joined copy); on a LocalStore the keys of ``write_once`` (objects nothing
        in a render reads back) go past the page cache (pipeline/store/direct_write.py)."""
        items = [(k, v if isinstance(v, tuple) else (v,)) for k, v in items]
        _counted("write_bytes", sum(len(p) for _, v in items for p in v))
        if self.root is not None:
            direct = frozenset(write_once)
            for key, parts in items:
                _write_object(os.path.join(self.root, key), parts, key in direct)
            return

        async def put():
            proto = default_buffer_prototype()
            await asyncio.gather(*(self.store.set(k, proto.buffer.from_bytes(b"".join(v))) for k, v in items))
        sync(put())

    def stamp(self, *keys: str):
        """((inode, mtime, ctime, size) or None per key) of LocalStore files or directories, and
        whether the listing or read that follows may be reused while the stamp stays the same:
        only when every mtime and ctime is older than LISTING_MARGIN_NS, so that any later
        change (rename into a directory, replacement of a file) gets a different one however
        coarse the file system's clock is (git's "racy index" rule)."""
        out, now = [], time.time_ns()
        for key in keys:
            try:
                st = os.stat(os.path.join(self.root, key))
            except FileNotFoundError:
                out.append(None)
                continue
            out.append((st.st_ino, st.st_mtime_ns, st.st_ctime_ns, st.st_size))
        reusable = all(s is None or max(s[1], s[2]) < now - LISTING_MARGIN_NS for s in out)
        return tuple(out), reusable


def _write_object(path: str, data: bytes | tuple[bytes, ...], direct: bool) -> None:
    """Write ``path`` atomically: a temp file beside it (``*.partial``, removed on failure), then
    a rename; ``data`` whole or as parts written one after the other; ``direct``: past the page
    cache where the file system allows it."""
    parts = data if isinstance(data, tuple) else (data,)
    head, name = os.path.split(path)
    tmp = os.path.join(head, f".{name}.{os.getpid()}.{id(parts):x}.partial")
    try:
        for first in (True, False):
            try:
                if not (direct and direct_write.write_new(tmp, parts[0] if len(parts) == 1 else b"".join(parts))):
                    with open(tmp, "wb") as fh:
                        for part in parts:
                            fh.write(part)
                break
            except FileNotFoundError:  # first object under this prefix
                if not first:
                    raise
                os.makedirs(head, exist_ok=True)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


@dataclass(frozen=True)
class _Prepared:
    """A batch ready to write: where, its sorted records (None unless kept), its hit counts,
    ``row`` (BATCH_FIELDS), and its summary."""

    frame: int
    batch: int
    records: SortedBatch | None
    counts: np.ndarray  # u64 (4, n_elements), this batch only
    row: tuple[int, int, int, int]  # BATCH_FIELDS
    summary: np.ndarray | None  # little-endian u32 words (write_batch's summarise)


@dataclass(frozen=True)
class StoreIdentity:
    """What a store's photons were made from: the scene, the photon settings' digest
    (pipeline/config.py PhotonConfig.photon_hash) and the run seed. A store never holds photons of
    two identities: it refuses to open or be made again with another."""

    scene_hash: str
    config_hash: str
    seed: int


def make_store(url: str | os.PathLike[str], read_only: bool) -> LocalStore | FsspecStore:
    """LocalStore for paths and file:// URLs (atomic renames), FsspecStore for other URLs."""
    text = os.fspath(url)
    if "://" not in text:
        return LocalStore(text, read_only=read_only)
    if text.startswith("file://"):
        return LocalStore(urllib.request.url2pathname(urllib.parse.urlparse(text).path),
                          read_only=read_only)
    return FsspecStore.from_url(text, read_only=read_only)


def local_path(url: str | os.PathLike[str]) -> Path | None:
    """The directory of a LocalStore URL (a path or file://), None for other stores."""
    text = os.fspath(url)
    if "://" not in text:
        return Path(text)
    if text.startswith("file://"):
        return Path(urllib.request.url2pathname(urllib.parse.urlparse(text).path))
    return None


def _file_stamp(path):
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return None
    return st.st_ino, st.st_mtime_ns, st.st_ctime_ns, st.st_size


_SHARED: dict = {}  # (path, mode) -> (stamp of zarr.json, PhotonStore): PhotonStore.open_shared


def _list_dir(store, prefix: str) -> list[str]:
    # zarr 3.1 has no public sync listing; zarr.core.sync.sync is what its own sync API uses
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
            raise LoomError("exists and is not a photon store (not a zarr group)", path=where) from None
        return None
    except zarr.errors.ContainsArrayError:
        raise LoomError("is a zarr array, not a photon store", path=where) from None
    except (ValueError, KeyError, TypeError) as err:
        raise LoomError(f"unreadable zarr metadata ({err})", path=where) from None


def _check_identity(attrs: dict, expected: dict, where: str) -> None:
    if attrs.get("format") != FORMAT:
        raise LoomError("is a zarr group but not a photon store (no format attribute)", path=where)
    if attrs.get("format_version") != FORMAT_VERSION:
        raise LoomError(f"photon store of format version {attrs.get('format_version')!r}; this photonloom reads "
                        f"version {FORMAT_VERSION}: delete it (its photons are traced again) or render into "
                        "another --out", path=where)
    for name, want in expected.items():
        if want is not None and attrs.get(name) != want and name != "keep_records":
            what = " (another scene file, or another clip of it: --animation)" if name == "scene_hash" else ""
            raise LoomError(f"store was made with {name}={attrs.get(name)!r}, not {want!r}{what}; "
                            "never mixed: use another store path", path=where, field=name)
    want = expected.get("keep_records")
    if want is not None and attrs.get("keep_records") != want:
        raise LoomError(("keeps hit records: give --keep-records to go on with it, or use another --out or --store"
                         if attrs.get("keep_records") else "holds no hit records (made without --keep-records): "
                         "use another --out or --store to keep them"), path=where, field="keep_records")


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
        self.keep_records: bool = bool(attrs["keep_records"])  # raw hit records beside the sums
        try:
            self._source = root["source"]
        except KeyError as err:
            raise LoomError(f"photon store is missing array {err}", path=url) from None
        # Per-instance caches of what never changes once written: the header of a done batch,
        # and (revalidated by a stat on a LocalStore) the done table and the sources.
        self._raw = _Raw(root.store)
        self._rows: dict[tuple[int, int], _Header] = {}
        self._done_cache = None
        self._source_cache = None
        # Decoded frames (FrameRecords of done batches never change): only open_shared instances
        # keep them, up to record_cache_bytes, least recently used out first
        self.record_cache_bytes = 0
        self._records: OrderedDict = OrderedDict()
        self._records_bytes = 0
        # The running counts of the last batch this instance wrote of each frame (least recently
        # written out first): the frame's next batch adds to them without reading them back
        self._running: OrderedDict[int, tuple[int, np.ndarray]] = OrderedDict()

    def __repr__(self) -> str:
        return (f"PhotonStore({self.url!r}, mode={self.mode!r}, frames={self.n_frames}, "
                f"elements={self.n_elements})")

    def __reduce__(self):
        # Dask ships the store by URL: each process reopens it (zarr arrays pickle poorly)
        return _reopen, (self.url, self.mode)

    # --- making and opening ---------------------------------------------------------------
    @classmethod
    def create(cls, url: str | os.PathLike[str], *, n_frames: int, n_elements: int, frame_numbers: Iterable[int],
               identity: StoreIdentity, keep_records: bool, max_batches: int = 16) -> PhotonStore:
        """Make the group and every fixed-size array; on an existing identical store, open it.

        Only the coordinator calls this. A store made with another identity or shape is refused.
        ``keep_records``: store every batch's raw hit records (20 bytes each) beside its sums, for
        re-estimation and research; without them a batch is its counts and sums alone.
        """
        where = os.fspath(url)
        n_frames = as_int(n_frames, "n_frames", where, 1)
        n_elements = as_int(n_elements, "n_elements", where, 1, ELEMENT_MASK + 2)
        max_batches = as_int(max_batches, "max_batches", where, 1, 1025)
        seed = as_int(identity.seed, "seed", where, 0)
        frame_numbers = [as_int(n, "frame number", where, -(1 << 62)) for n in frame_numbers]
        if len(frame_numbers) != n_frames:
            raise LoomError(f"{len(frame_numbers)} frame_numbers for {n_frames} frames", path=where)
        for name, value in (("scene_hash", identity.scene_hash), ("config_hash", identity.config_hash)):
            if not isinstance(value, str) or not value:
                raise LoomError(f"{name} must be a non-empty string", path=where)
        if not isinstance(keep_records, bool):
            raise TypeError(f"keep_records must be a bool, not {keep_records!r}")  # a caller's bug
        attrs = dict(scene_hash=identity.scene_hash, config_hash=identity.config_hash, seed=seed,
                     keep_records=keep_records, n_frames=n_frames, n_elements=n_elements,
                     frame_numbers=frame_numbers, max_batches=max_batches)
        try:
            store = make_store(url, read_only=False)
            root = _open_root(store, where, "r+")
            if root is not None:
                _check_identity(dict(root.attrs), attrs, where)
                if root.attrs.get("complete"):
                    return cls(root, where, "r+")
            else:
                root = zarr.create_group(store=store, attributes=dict(
                    format=FORMAT, format_version=FORMAT_VERSION, complete=False, **attrs,
                    record_layout=cls._layout_description(), count_categories=list(CATEGORIES),
                    batch_fields=list(BATCH_FIELDS)))
            cls._make_arrays(root, n_frames, n_elements, max_batches, keep_records)
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
                "order": "element, key, b1, b2, energy bits",
                "batch_array": "frames/<f>/<b>: (5, n) u32, rows key, b1 | b2 << 16, energy R, G, B bits"}

    @staticmethod
    def _make_arrays(root: zarr.Group, n_frames: int, n_elements: int, max_batches: int, keep_records: bool) -> None:
        # The batch objects (batch/c.f.b) are written and read by the store itself, no zarr array
        root.create_array("source", shape=(n_frames,), chunks=(n_frames,), dtype="int32",
                          fill_value=-1, overwrite=True, compressors=records_codec())
        # frames/<f> groups are written with a frame's first batch (_write_payload): making all of
        # them here cost 13 ms a frame, 20 minutes before the first photon of a 100,000-frame timeline
        if keep_records:
            root.require_group("frames")

    @classmethod
    def open(cls, url: str | os.PathLike[str], *, identity: StoreIdentity | None = None,
             keep_records: bool | None = None, mode: str = "r") -> PhotonStore:
        """Open an existing store, refusing one made with another ``identity`` (scene, photon
        settings or seed) or, if given, ``keep_records``."""
        where = os.fspath(url)
        if mode not in ("r", "r+"):
            raise ValueError(f"mode must be 'r' or 'r+', not {mode!r}")  # a caller's bug, not the user's
        try:
            store = make_store(url, read_only=(mode == "r"))
            root = _open_root(store, where, mode)
        except OSError as err:
            raise LoomError(f"cannot open photon store: {err.strerror or err}", path=where) from None
        if root is None:
            raise LoomError("no photon store here", path=where)
        expected = {} if identity is None else asdict(identity)
        _check_identity(dict(root.attrs), dict(expected, keep_records=keep_records), where)
        if not root.attrs.get("complete"):
            raise LoomError("photon store creation was interrupted; run create again", path=where)
        return cls(root, where, mode)

    @classmethod
    def open_shared(cls, url: str | os.PathLike[str], mode: str = "r") -> PhotonStore:
        """:meth:`open`, but reusing this process's instance for ``(url, mode)`` while the store's
        root metadata is the same file (LocalStore only; a new store at the URL is a new file):
        tasks of one worker then share its caches and skip reopening (3 ms a task)."""
        path = local_path(url)
        if path is None:
            return cls.open(url, mode=mode)
        stamp = _file_stamp(path / "zarr.json")
        found = _SHARED.get((str(path), mode))
        if found is not None and stamp is not None and found[0] == stamp:
            return found[1]
        store = cls.open(url, mode=mode)
        if stamp is not None:
            store.record_cache_bytes = RECORD_CACHE_BYTES
            _SHARED[(str(path), mode)] = (stamp, store)
            while len(_SHARED) > 8:
                _SHARED.pop(next(iter(_SHARED)))
        return store

    # --- what is done ---------------------------------------------------------------------
    def _frame(self, frame_index, name: str = "frame_index") -> int:
        return as_int(frame_index, name, self.url, 0, self.n_frames)

    def _done_table(self) -> np.ndarray:
        """bool (n_frames, max_batches), read-only: the done batches, from one directory listing
        of ``batch/`` and the headers of the objects listed (:meth:`_prefixes`; a done batch's
        header is read once per instance). On a LocalStore the table is reused while the
        directory is unchanged (:meth:`_Raw.stamp`)."""
        store = self._root.store
        stamp, reusable = None, False
        if self._raw.root is not None:
            stamp, reusable = self._raw.stamp("batch")
            if self._done_cache is not None and self._done_cache[0] == stamp:
                return self._done_cache[1]
            try:
                names = os.listdir(os.path.join(self._raw.root, "batch")) if stamp[0] is not None else []
            except NotADirectoryError:  # not a store we can write: its writers say so
                names = []
        elif store.supports_listing:
            names = _list_dir(store, "batch")
        else:
            names = None  # every header is asked for
        listed = np.zeros((self.n_frames, self.max_batches), dtype=bool)
        if names is None:
            listed[:] = True
        for name in names or ():
            m = _BATCH_OBJECT.fullmatch(name)
            if m and int(m[1]) < self.n_frames and int(m[2]) < self.max_batches:
                listed[int(m[1]), int(m[2])] = True
        runs = np.cumprod(listed, axis=1).sum(axis=1)  # objects present from batch 0 on
        done = np.zeros_like(listed)
        for f, heads in self._prefixes({int(f): int(runs[f]) for f in np.flatnonzero(runs)}).items():
            done[f, :len(heads)] = True
        done.flags.writeable = False
        if stamp is not None and reusable:
            self._done_cache = (stamp, done)
        return done

    def _sources(self) -> np.ndarray:
        """int64 (n_frames,): the frame whose photons each frame uses (read-only). On a
        LocalStore reused while the source array's chunk and directories are unchanged."""
        where = ("source", "source/c", "source/c/0")
        stamp, reusable = self._raw.stamp(*where) if self._raw.root is not None else (None, False)
        if stamp is not None and self._source_cache is not None and self._source_cache[0] == stamp:
            return self._source_cache[1]
        src = self._source[...].astype(np.int64)
        out = np.where(src < 0, np.arange(self.n_frames), src)
        out.flags.writeable = False
        if reusable and stamp == self._raw.stamp(*where)[0]:
            self._source_cache = (stamp, out)
        return out

    def source_frame(self, frame_index: int) -> int:
        """The frame whose photons ``frame_index`` uses (itself unless shared)."""
        return int(self._sources()[self._frame(frame_index)])

    @staticmethod
    def _batch_key(frame: int, batch: int) -> str:
        return f"batch/c.{frame}.{batch}"

    def _prefixes(self, wanted: dict[int, int]) -> dict[int, list[_Header]]:
        """For each ``{frame: n}`` the headers of the frame's done batches among 0..n-1: the
        longest prefix of objects whose headers are whole and name their batch, each batch
        starting where the one before ends. A done batch never changes, so its header is read
        once per instance; the others are read again whenever asked (a rerun rewrites them)."""
        missing = [(f, b) for f, n in wanted.items() for b in range(n) if (f, b) not in self._rows]
        got = {}
        if missing:
            data = self._raw.get_many([self._batch_key(f, b) for f, b in missing], [(0, HEAD)] * len(missing))
            got = {(f, b): _Header.parse(d, f, b) for (f, b), d in zip(missing, data)}
        out = {}
        for f, n in wanted.items():
            heads, end = [], 0
            for b in range(n):
                head = self._rows.get((f, b)) or got.get((f, b))
                if head is None or head.photon_start != end:
                    break
                self._rows[(f, b)] = head
                heads.append(head)
                end = head.photon_start + head.photons_emitted
            out[f] = heads
        return out

    def _header(self, frame: int, batch: int) -> _Header | None:
        """The header of (frame, batch) if the batch is done (batches 0..batch done), else None."""
        heads = self._prefixes({frame: batch + 1})[frame]
        return heads[batch] if len(heads) > batch else None

    def _meta(self, frame: int, batches) -> np.ndarray:
        """u64 (len(batches), BATCH_FIELDS) of done batches of a frame."""
        batches = [int(b) for b in batches]
        if not batches:
            return np.zeros((0, len(BATCH_FIELDS)), np.uint64)
        heads = self._prefixes({frame: max(batches) + 1})[frame]
        if max(batches) >= len(heads):
            raise LoomError(f"frame {frame}: batch {len(heads)} is no longer done (its object changed or is "
                            "damaged)", path=self.url)
        return np.array([heads[b][:len(BATCH_FIELDS)] for b in batches], np.uint64)

    def is_done(self, frame_index: int, batch: int) -> bool:
        """Whether (frame, batch) is done: a rerun of the task can be skipped."""
        f = self.source_frame(frame_index)
        return self._header(f, as_int(batch, "batch", self.url, 0, self.max_batches)) is not None

    def done_batches(self, frame_index: int) -> list[int]:
        """Done batches of a frame (of its source frame, if shared): always 0..k-1."""
        f = self.source_frame(frame_index)
        return [int(b) for b in np.flatnonzero(self._done_table()[f])]

    def batches_per_frame(self) -> np.ndarray:
        """int (n_frames,): done batches of every frame (of its source frame, if shared)."""
        return self._done_table().sum(axis=1)[self._sources()]

    def photons_emitted(self, frame_index: int) -> int:
        """Photons emitted for a frame, summed over its done batches."""
        f = self.source_frame(frame_index)
        return int(self._meta(f, self.done_batches(f))[:, 1].sum())

    def photons_in(self, frame_index: int, n_batches: int) -> int:
        """Photons emitted by a frame's first ``n_batches`` done batches (a prefix in use)."""
        f = self.source_frame(frame_index)
        done = self.done_batches(f)
        if not 0 <= n_batches <= len(done):
            raise LoomError(f"frame {f}: {n_batches} batches asked, {len(done)} done", path=self.url)
        return int(self._meta(f, done[:n_batches])[:, 1].sum())

    def emitted(self, batches: npt.ArrayLike | None = None) -> np.ndarray:
        """int64 (n_frames,): photons emitted per frame by its first ``batches[f]`` done batches
        (of its source frame, if shared), or by all its done batches (None): one
        :meth:`photons_in` per frame, vectorised."""
        sources, done = self._sources(), self._done_table()
        n_done = done.sum(axis=1)
        use = n_done[sources] if batches is None else np.asarray(batches, np.int64).reshape(-1)
        if use.shape != (self.n_frames,):
            raise LoomError(f"emitted: {use.shape[0]} batch counts for {self.n_frames} frames", path=self.url)
        out = np.zeros(self.n_frames, np.int64)
        bad = np.flatnonzero((use < 0) | (use > n_done[sources]))
        if len(bad):
            g = int(sources[bad[0]])
            raise LoomError(f"frame {g}: {int(use[bad[0]])} batches asked, {int(n_done[g])} done", path=self.url)
        for g in np.unique(sources[use > 0]):  # only frames with photons: a long timeline has few
            mine = np.flatnonzero(sources == g)
            running = np.concatenate([[0], np.cumsum(self._meta(int(g), range(int(use[mine].max())))[:, 1]
                                                     .astype(np.int64))])
            out[mine] = running[use[mine]]
        return out

    def shared_batches(self, batches: npt.ArrayLike) -> np.ndarray:
        """int64 (n_frames,): ``batches`` with each frame given the count of the first frame using
        the same source frame, which is what :meth:`counts` uses for all of them; so a subset of
        frames gets the counts it would get within the whole table."""
        use = np.asarray(batches, np.int64).reshape(-1)
        sources = self._sources()
        order = np.arange(self.n_frames)[::-1]
        first = np.empty(self.n_frames, np.int64)
        first[sources[order]] = order  # the last write of a source, its first frame, wins
        return use[first[sources]]

    def prefix_for(self, frame_index: int, n_photons: int) -> int | None:
        """The fewest leading done batches of a frame holding at least ``n_photons`` photons, or
        None when all of them hold fewer (a batch must be shot first)."""
        return self.prefixes_for({frame_index: n_photons})[frame_index]

    def prefixes_for(self, targets: dict[int, int]) -> dict[int, int | None]:
        """:meth:`prefix_for` of every ``{frame_index: n_photons}``, the store's tables read once:
        one frame at a time re-reads them for every frame while they are younger than
        LISTING_MARGIN_NS, as they are right after a store is made or a batch lands (135 frames:
        60-90 ms that the coordinator spent before its first and after its last photon task)."""
        sources, done = self._sources(), self._done_table()
        out: dict[int, int | None] = {}
        for frame_index, n_photons in targets.items():
            f = int(sources[self._frame(frame_index)])
            running = np.cumsum(self._meta(f, np.flatnonzero(done[f]))[:, 1].astype(np.int64))
            reach = np.flatnonzero(running >= n_photons)
            out[frame_index] = int(reach[0]) + 1 if len(reach) else (0 if n_photons <= 0 else None)
        return out

    def source_frames(self) -> np.ndarray:
        """int64 (n_frames,), read-only: :meth:`source_frame` of every frame."""
        return self._sources()

    def batch_info(self, frame_index: int, batch: int) -> dict[str, int] | None:
        """The header of a done batch as a dict of BATCH_FIELDS, or None if not done."""
        f = self.source_frame(frame_index)
        head = self._header(f, as_int(batch, "batch", self.url, 0, self.max_batches))
        return None if head is None else dict(zip(BATCH_FIELDS, head))

    # --- writing --------------------------------------------------------------------------
    def _writable(self) -> None:
        if self.mode != "r+":
            raise LoomError("photon store is open read-only (mode='r')", path=self.url)

    def write_batch(self, frame_index: int, batch: int, photons: PhotonBatch, *,
                    summarise: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None = None) -> bool:
        """Write one batch of ``photons`` (their records and the range of photons emitted), its batch
        object last. Returns False if it was already done.

        Rerunning a batch rewrites identical bytes; a done batch is only compared by digest and
        a different one is refused (non-deterministic tracer). Batch b needs b-1 done.
        ``summarise``: u32 words derived from the batch's checked (key, bary, energy) in the order
        given (pipeline/collection/batch_sums.py summariser), stored in the batch object
        (:meth:`read_summary`): what a render reads of the batch; or (words, counts) with the
        records' :func:`~pipeline.store.records.category_counts` as a summariser that groups them
        by element counts them anyway (the store then does not count them again). Only a store
        that keeps records may go without; only such a store sorts them into the total order.
        """
        if summarise is None and not self.keep_records:
            raise ValueError("a store without records needs the batch's summary (summarise)")  # a caller's bug
        prepared = self._prepare(frame_index, batch, photons, summarise)
        done = self._header(prepared.frame, prepared.batch)
        if done is not None:
            if tuple(done[:len(BATCH_FIELDS)]) == prepared.row:
                return False
            raise LoomError("is already done with different photons (digest, count or range "
                            "differ): the tracer is not deterministic", path=self.url,
                            field=f"frame {prepared.frame} batch {prepared.batch}")
        self._write_payload(prepared)
        self._mark_done(prepared)
        return True

    def _prepare(self, frame_index, batch, photons: PhotonBatch, summarise) -> _Prepared:
        """Validate a batch, make its counts and summary, and sort its records if they are kept
        (reads only the previous batch's header). The digest is of the sorted records where they
        are kept, else of the summary and counts: what the batch stores."""
        self._writable()
        f, b = self._frame(frame_index), as_int(batch, "batch", self.url, 0, self.max_batches)
        where = f"{self.url}: frame {f} batch {b}"
        src = int(self._sources()[f])
        if src != f:
            raise LoomError(f"frame {f} shares the photons of frame {src}; write to {src}",
                            path=where)
        key, bary, energy = check_records(photons.key, photons.bary, photons.energy, self.n_elements, where)
        emitted = as_int(photons.photons_emitted, "photons_emitted", where, 1)
        start = as_int(photons.photon_start, "photon_start", where, 0)
        expected_start = 0
        if b > 0:
            prev = self._header(f, b - 1)
            if prev is None:
                raise LoomError(f"batch {b - 1} is not done; batches are written in order",
                                path=where)
            expected_start = prev.photon_start + prev.photons_emitted
        if start != expected_start:
            raise LoomError(f"photon_start {start} is not contiguous: the previous batch ends at "
                            f"{expected_start}", path=where)
        summary = counts = None
        if summarise is not None:
            made = summarise(key, bary, energy)
            summary, counts = made if isinstance(made, tuple) else (made, None)
            summary = np.asarray(summary)
            if summary.dtype != np.uint32 or summary.ndim != 1:
                raise TypeError(f"a batch summary is 1-D u32 words, not {summary.dtype} {summary.shape}")
            summary = np.ascontiguousarray(summary, "<u4")
            if counts is not None:  # the summariser's own count of the records (category_counts)
                counts = np.asarray(counts)
                if counts.shape != (len(CATEGORIES), self.n_elements) or counts.dtype.kind not in "ui" \
                        or int(counts.sum(dtype=np.uint64)) != key.shape[0]:
                    raise TypeError(f"a summariser's hit counts are ({len(CATEGORIES)}, {self.n_elements}) integers "
                                    f"adding up to the {key.shape[0]} records, not {counts.dtype} {counts.shape}")
        records = sorted_batch(key, bary, energy, self.n_elements) if self.keep_records else None
        if records is not None:
            counts = records.counts
        elif counts is None:
            counts = category_counts(key, self.n_elements)
        counts = np.asarray(counts, np.uint64)
        # Without records, one pass over the summary and the counts (u32, as stored), no joined copy
        digest = records.digest(start, emitted) if records is not None else \
            parts_digest([summary, counts.astype("<u4")], start, emitted)
        return _Prepared(f, b, records, counts, (start, emitted, int(key.shape[0]), digest), summary)

    def _write_payload(self, p: _Prepared) -> None:
        """The records of one batch, if the store keeps them: everything written before its
        batch object.

        The records are one (5, n) u32 zarr array at ``frames/<f>/<b>``, its metadata and chunks
        written as whole objects (no zarr call): identical bytes on a rerun, written over
        identical objects, and nothing is ever deleted, so a duplicate task cannot expose a done
        batch with missing chunks. zarr reads the array as any other.
        """
        if not self.keep_records:
            return
        base, n = f"frames/{p.frame}/{p.batch}", len(p.records)
        rows = max(1, min(n, RECORD_CHUNK))
        block = p.records.packed()
        items = [(f"{base}/c.0.{i}", _encode_rows(self._chunk(block, i * rows, rows)))
                 for i in range(max(1, -(-n // rows)))]
        # Only the records' chunks skip the page cache: a render reads the batch object
        bulk = [k for k, _ in items]
        items.append((f"{base}/zarr.json", _batch_metadata(n, rows)))
        if p.batch == 0:  # the frame's group, as zarr writes it (bytes equal to require_group's)
            items.append((f"frames/{p.frame}/zarr.json", _GROUP_METADATA))
        self._raw.set_many(items, write_once=bulk)

    def _mark_done(self, p: _Prepared) -> None:
        """Write the batch object (header, running counts, summary) in one atomic write: the
        batch is done."""
        running = p.counts
        if p.batch > 0:
            kept = self._running.get(p.frame)
            running = running + (kept[1] if kept is not None and kept[0] == p.batch - 1
                                 else self._count_chunks([(p.frame, p.batch - 1)])[0])
        if running.size and running.max() > np.iinfo(np.uint32).max:
            raise LoomError("per-element hit count overflows u32", path=self.url)
        running = running.astype(np.uint32)
        counts = _encode_rows(running)
        words = b"" if p.summary is None else _encode_rows(p.summary)
        head = _Header(*p.row, len(counts), zlib.crc32(counts), NO_SUMMARY if p.summary is None else p.summary.size,
                       len(words), zlib.crc32(words))
        self._raw.set_many([(self._batch_key(p.frame, p.batch), (head.pack(p.frame, p.batch), counts, words))])
        self._rows[(p.frame, p.batch)] = head
        self._running.pop(p.frame, None)
        self._running[p.frame] = (p.batch, running)
        while len(self._running) * running.nbytes > RUNNING_CACHE_BYTES:
            self._running.popitem(last=False)

    def read_summary(self, frame_index: int, batch: int, *, use: Callable[[np.ndarray], T] | None = None
                     ) -> np.ndarray | T | None:
        """The u32 words of the summary a done batch's writer stored
        (``write_batch(summarise=...)``), or None when the batch is not done, has none, or its
        summary is damaged (its CRC or length; a warning). With ``use``: ``use(words)`` of words
        read and decompressed into this thread's scratch arrays (records.scratch: no new memory a
        batch), valid only during the call."""
        f = self.source_frame(frame_index)
        b = as_int(batch, "batch", self.url, 0, self.max_batches)
        head = self._header(f, b)
        if head is None or head.n_words == NO_SUMMARY:
            return None
        words = self._summary_words(f, b, head, reuse=use is not None)
        return words if use is None or words is None else use(words)

    def _summary_words(self, f: int, b: int, head: _Header, reuse: bool = False) -> np.ndarray | None:
        """The summary words of a done batch, checked (its CRC-32 and length); ``reuse``: in the
        thread's scratch arrays."""
        data = self._raw.get_into(self._batch_key(f, b), HEAD + head.counts_bytes,
                                  scratch("summary_bytes", head.words_bytes, np.uint8) if reuse
                                  else np.empty(head.words_bytes, np.uint8))
        words = None
        if data is not None and len(data) == head.words_bytes and zlib.crc32(data) == head.words_crc \
                and int.from_bytes(bytes(data[4:8]), "little") == 4 * head.n_words:  # blosc header: bytes out
            words = scratch("summary_words", head.n_words, "<u4") if reuse else np.empty(head.n_words, "<u4")
            try:
                numcodecs.blosc.decompress(data, words)
            except (ValueError, RuntimeError):
                words = None
        if words is None:
            log.warning("%s: frame %d batch %d: damaged batch summary ignored", self.url, f, b)
        return words

    def _count_chunks(self, pairs) -> list[np.ndarray]:
        """u32 (4, n_elements) running counts of (frame, batch) pairs, zeros where not done,
        decoded straight from the batch objects."""
        shape = (len(CATEGORIES), self.n_elements)
        out = [np.zeros(shape, np.uint32) for _ in pairs]
        todo = [(i, f, b, head) for i, (f, b) in enumerate(pairs) if (head := self._header(f, b)) is not None]
        data = self._raw.get_many([self._batch_key(f, b) for _, f, b, _ in todo],
                                  [(HEAD, head.counts_bytes) for *_, head in todo])
        for (i, f, b, head), got in zip(todo, data):
            try:
                if got is None or len(got) != head.counts_bytes or zlib.crc32(got) != head.counts_crc:
                    raise ValueError("damaged")
                out[i] = _decode(got, "<u4", shape[0] * shape[1]).reshape(shape)
            except (ValueError, RuntimeError):
                raise LoomError(f"frame {f} batch {b}: damaged hit counts; delete the photon store to trace its "
                                "photons again", path=self.url) from None
        return out

    @staticmethod
    def _chunk(block: np.ndarray, lo: int, rows: int) -> np.ndarray:
        """Chunk of ``rows`` records from ``lo``, padded with the fill value as zarr pads edges."""
        part = block[:, lo:lo + rows]
        if part.shape[1] < rows:
            part = np.concatenate([part, np.zeros((5, rows - part.shape[1]), np.uint32)], axis=1)
        return part

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
        self._source_cache = None

    # --- reading --------------------------------------------------------------------------
    def _records_kept(self) -> None:
        if not self.keep_records:
            raise LoomError("holds no hit records (made without --keep-records): render with --keep-records "
                            "to read them", path=self.url)

    def read_frame(self, frame_index: int, *, batches: Iterable[int] | None = None) -> FrameRecords:
        """All records of a frame's done batches (or of ``batches``), sorted by element; only a
        store that keeps records has them."""
        self._records_kept()
        f = self._frame(frame_index)
        g = int(self._sources()[f])
        done = self.done_batches(g)
        if batches is None:
            chosen = done
        else:
            chosen = sorted({as_int(b, "batch", self.url, 0, self.max_batches) for b in batches})
            missing = [b for b in chosen if b not in done]
            if missing:
                raise LoomError(f"frame {f}: batch(es) {missing} not done", path=self.url)
        key = (f, g, tuple(chosen))
        found = self._records.get(key)
        if found is not None:
            self._records.move_to_end(key)
            return found
        meta = self._meta(g, chosen)
        parts, dropped = [], 0
        for b, row in zip(chosen, meta):
            rows, bad = valid_records(self._read_rows(g, b, int(row[2])), self.n_elements)
            if bad:
                log.warning("%s: frame %d batch %d: %d damaged record(s) dropped (NaN, infinite or negative "
                            "energy, or an unknown element)", self.url, g, b, bad)
            dropped += bad
            parts.append(unpack_records(rows, self.n_elements))
        records = FrameRecords.merge(f, g, chosen, parts, self.n_elements, int(meta[:, 1].sum()), dropped)
        if self.record_cache_bytes > 0:
            self._keep(key, records)
        return records

    def _keep(self, key, records: FrameRecords) -> None:
        arrays = [v for v in vars(records).values() if isinstance(v, np.ndarray)]
        size = sum(a.nbytes for a in arrays)
        if size > self.record_cache_bytes:
            return
        for a in arrays:
            a.flags.writeable = False  # shared by every later reader of the frame
        self._records[key] = records
        self._records_bytes += size
        while self._records_bytes > self.record_cache_bytes:
            _, old = self._records.popitem(last=False)
            self._records_bytes -= sum(v.nbytes for v in vars(old).values() if isinstance(v, np.ndarray))

    def verify_batch(self, frame_index: int, batch: int) -> bool:
        """Re-read a done batch and check it: its counts and summary (if any) against their
        CRC-32 in its header, and its records (if kept) against the header's digest."""
        f = self.source_frame(frame_index)
        b = as_int(batch, "batch", self.url, 0, self.max_batches)
        head = self._header(f, b)
        if head is None:
            return False
        try:
            self._count_chunks([(f, b)])
        except LoomError:
            return False
        if head.n_words != NO_SUMMARY:
            if self._summary_words(f, b, head) is None:
                return False
        elif not self.keep_records:
            return False
        if not self.keep_records:
            return True
        rows = self._read_rows(f, b, head.n_records)
        return records_digest(rows, head.photon_start, head.photons_emitted) == head.digest

    def _read_rows(self, f: int, b: int, n: int) -> np.ndarray:
        """u32 (5, n): the packed rows of a done batch of ``n`` records."""
        rows = max(1, min(n, RECORD_CHUNK))
        keys = [f"frames/{f}/{b}/c.0.{i}" for i in range(max(1, -(-n // rows)))]
        try:
            parts = [_decode(data, "<u4", 5 * rows).reshape(5, rows)
                     for data in self._raw.get_many(keys) if data is not None]
            if len(parts) != len(keys):
                raise ValueError("missing chunk")
        except (ValueError, RuntimeError):
            raise LoomError(f"frame {f} batch {b}: records do not match its batch object ({n})",
                            path=self.url) from None
        block = parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)
        return block[:, :n]

    def counts(self, kind: str = "all", frames: Iterable[int] | None = None, parity: int | None = None,
               batches: npt.ArrayLike | None = None) -> np.ndarray:
        """u32 (len(frames), n_elements) hit counts over done batches, without reading records.

        ``kind`` is "direct", "indirect" or "all"; ``parity`` 0/1 keeps even/odd photons only.
        ``frames`` (default all) may repeat or be shared frames. ``batches`` (one per frame, or
        None: all done) is the number of leading batches in use. One chunk read per frame: the
        running counts at its last batch in use.
        """
        if kind not in ("direct", "indirect", "all") or parity not in (None, 0, 1):
            raise ValueError(f"counts(kind={kind!r}, parity={parity!r}): kind must be direct, "
                             "indirect or all and parity None, 0 or 1")  # a caller's bug
        cats = [c for c in range(len(CATEGORIES))
                if (kind == "all" or (c >> 1) == (kind == "direct"))
                and (parity is None or (c & 1) == parity)]
        chosen = (np.arange(self.n_frames) if frames is None
                  else np.array([self._frame(f, "frame") for f in frames], dtype=np.int64))
        sources = self._sources()[chosen]
        unique, inverse = np.unique(sources, return_inverse=True)
        last = self._done_table()[unique].sum(axis=1) - 1  # done batches are a prefix
        if batches is not None:
            use = np.asarray(batches, np.int64).reshape(-1)
            if use.shape != chosen.shape:
                raise LoomError(f"counts: {use.shape[0]} batch counts for {chosen.shape[0]} frames", path=self.url)
            first = np.zeros(unique.shape[0], np.int64)
            first[inverse.reshape(-1)[::-1]] = np.arange(chosen.shape[0])[::-1]
            want = use[first] - 1
            if (want > last).any():
                raise LoomError("counts: more batches asked than done", path=self.url)
            last = want
        table = np.zeros((unique.shape[0], self.n_elements), dtype=np.uint32)
        rows = np.flatnonzero(last >= 0)
        for i in range(0, rows.shape[0], 64):  # bounded memory: 64 chunks per read
            part = rows[i:i + 64]
            pairs = [(int(unique[j]), int(last[j])) for j in part]
            for j, data in zip(part, self._count_chunks(pairs)):
                table[j] = data[cats[0]] if len(cats) == 1 else data[cats].sum(axis=0, dtype=np.uint32)
        return table[inverse.reshape(-1)]


def _reopen(url: str, mode: str) -> PhotonStore:
    return PhotonStore.open(url, mode=mode)


def remove_partials(url: str) -> int:
    """Delete the temp files killed writers left in a local store (ours ``.NAME.PID.ID.partial`` and
    zarr LocalStore's ``*.partial``); returns how many. Call it only when no writer of the store is
    alive (a run that has finished all its writes): zarr never reads them, but they take space and
    a rerun should leave a clean store. Remote stores write objects whole and have none."""
    if "://" in url and not url.startswith("file://"):
        return 0
    root = Path(url.removeprefix("file://"))
    removed = 0
    for tmp in root.rglob("*.partial"):
        tmp.unlink(missing_ok=True)
        removed += 1
    return removed


def disk_usage(url: str) -> dict[str, int] | None:
    """Bytes on disk of a local store by part: ``photons`` (batch objects: counts and sums; sharing
    table), ``records`` (hit records, kept on request) and ``maps`` (illumination/); None for a
    remote store, whose size its object store tells."""
    root = local_path(url)
    if root is None or not root.is_dir():
        return None
    parts = {"photons": 0, "records": 0, "maps": 0}
    for path in root.rglob("*"):
        if path.is_file():
            top = path.relative_to(root).parts[0]
            parts["records" if top == "frames" else "maps" if top == "illumination" else "photons"] += \
                path.stat().st_size
    return parts
