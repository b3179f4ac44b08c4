"""Illumination maps in the run's photon store: per frame, vertex irradiance of the element mesh.

Arrays under ``illumination/`` in the photon store's zarr group (layout of the rest in
``pipeline.store``)::

    illumination/
      indirect    (F, V, 3) f32, chunk (1, V, 3), lz4 + shuffle: irradiance from indirect photon
                hits (W/m^2)
      direct      (F, V, 3) f32, chunk (1, V, 3), lz4 + shuffle: mesh-based direct estimate (eye
                adaptation, §4)
      adaptation  (F,) f64, chunk (1,), uncompressed, fill NaN: the frame's adaptation luminance L_wa

Everything here is recomputed from the photons, so a rewrite simply overwrites. Only the
coordinator creates the arrays (:meth:`IlluminationMaps.create`; arrays of other shapes or codecs
are made anew); a frame task writes its own chunks, one writer each, and ``adaptation`` last: a
finite value there means the frame is done. The chunks are encoded and written by the store
itself (``_Raw``, temp file + rename on a LocalStore: a chunk is whole or absent), 0.1 ms a frame
where three zarr writes took 7; zarr reads them as any other.
"""
from __future__ import annotations

import os

import numpy as np
import zarr
import zarr.errors

from ..errors import LoomError
from .photon_store import FLAT_KEYS, _encode_rows, _file_stamp, _Raw, local_path, make_store, table_codec

GROUP = "illumination"
_SHARED: dict = {}  # (path, mode) -> (metadata stamps, IlluminationMaps): IlluminationMaps.open_shared
MAPS = ("indirect", "direct")


class IlluminationMaps:
    """The illumination arrays of one photon store (``url``)."""

    def __init__(self, group: zarr.Group, url: str):
        self.url = url
        self._group = group
        try:
            self._maps = {name: group[name] for name in MAPS}
            self._adaptation = group["adaptation"]
        except KeyError as err:
            raise LoomError(f"illumination maps are missing array {err}", path=url) from None
        self.n_frames, self.n_vertices = self._maps["indirect"].shape[:2]
        self._raw = _Raw(group.store)
        self._prefix = f"{group.path}/" if group.path else ""
        # Chunks are encoded here only for arrays with the codecs create() gives (else zarr writes)
        self._own = all(_as_created(self._group, name) for name in (*MAPS, "adaptation"))

    @classmethod
    def create(cls, url: str | os.PathLike[str], *, n_frames: int, n_vertices: int) -> IlluminationMaps:
        """Make (or reuse, when the shapes fit) the arrays in the photon store at ``url``."""
        where = os.fspath(url)
        root = _root(where, "r+")
        group = root.require_group(GROUP)
        shape = (n_frames, n_vertices, 3)
        fits = all(name in group and group[name].shape == shape for name in MAPS) \
            and "adaptation" in group and group["adaptation"].shape == (n_frames,) \
            and all(_as_created(group, name) for name in (*MAPS, "adaptation"))
        if not fits:
            for name in MAPS:
                group.create_array(name, shape=shape, chunks=(1, n_vertices, 3), dtype="float32",
                                   fill_value=0.0, compressors=table_codec(), overwrite=True,
                                   chunk_key_encoding=FLAT_KEYS)
            group.create_array("adaptation", shape=(n_frames,), chunks=(1,), dtype="float64",
                               fill_value=np.nan, compressors=None, overwrite=True,
                               chunk_key_encoding=FLAT_KEYS)
        return cls(group, where)

    @classmethod
    def open(cls, url: str | os.PathLike[str], mode: str = "r") -> IlluminationMaps:
        where = os.fspath(url)
        root = _root(where, mode)
        if GROUP not in root:
            raise LoomError("the photon store has no illumination maps yet", path=where)
        return cls(root[GROUP], where)

    @classmethod
    def open_shared(cls, url: str | os.PathLike[str], mode: str = "r") -> IlluminationMaps:
        """:meth:`open`, reusing this process's instance while the arrays' metadata files are
        the same (LocalStore only; :meth:`create` with other shapes writes new ones)."""
        path = local_path(url)
        if path is None:
            return cls.open(url, mode)
        stamp = tuple(_file_stamp(path / GROUP / name / "zarr.json") for name in (*MAPS, "adaptation"))
        key = (str(path), mode)
        found = _SHARED.get(key)
        if found is not None and None not in stamp and found[0] == stamp:
            return found[1]
        maps = cls.open(url, mode)
        if None not in stamp:
            _SHARED[key] = (stamp, maps)
            while len(_SHARED) > 8:
                _SHARED.pop(next(iter(_SHARED)))
        return maps

    def write_frame(self, frame_index: int, *, indirect: np.ndarray, direct: np.ndarray,
                    adaptation: float) -> None:
        """Write one frame's maps, then its adaptation luminance (the done marker)."""
        f = self._index(frame_index)
        maps = {}
        for name, data in (("indirect", indirect), ("direct", direct)):
            data = np.asarray(data, dtype=np.float32)
            if data.shape != (self.n_vertices, 3) or not np.isfinite(data).all():
                raise LoomError(f"{name} map must be finite ({self.n_vertices}, 3), got {data.shape}",
                                path=self.url)
            maps[name] = data
        if not np.isfinite(adaptation) or adaptation <= 0:
            raise LoomError(f"adaptation luminance {adaptation!r} must be positive", path=self.url)
        if not self._own:
            for name, data in maps.items():
                self._maps[name][f] = data
            self._adaptation[f] = float(adaptation)
            return
        # The maps' chunks, then the adaptation chunk (the done marker) in a second write
        self._raw.set_many([(f"{self._prefix}{name}/c.{f}.0.0", _encode_rows(data))
                            for name, data in maps.items()])
        self._raw.set_many([(f"{self._prefix}adaptation/c.{f}", np.array([adaptation], "<f8").tobytes())])

    def read(self, frame_index: int, name: str = "indirect") -> np.ndarray:
        """(V, 3) float32 map of a done frame."""
        f = self._index(frame_index)
        if not self.is_done(f):
            raise LoomError(f"frame index {f} has no illumination map", path=self.url)
        return self._maps[name][f]

    def adaptation(self) -> np.ndarray:
        """(F,) adaptation luminance of every frame, NaN where not done."""
        return self._adaptation[...]

    def is_done(self, frame_index: int) -> bool:
        return bool(np.isfinite(self._adaptation[self._index(frame_index)]))

    def _index(self, frame_index) -> int:
        f = int(frame_index)
        if not 0 <= f < self.n_frames:
            raise LoomError(f"frame index {f} out of range [0, {self.n_frames})", path=self.url)
        return f


def _as_created(group: zarr.Group, name: str) -> bool:
    """Whether an array has the dtype, codecs and chunk keys :meth:`IlluminationMaps.create` gives
    it, which the store's own chunk writer assumes."""
    arr = group[name]
    want = ("float64", ()) if name == "adaptation" else ("float32", (table_codec(),))
    return (str(arr.dtype), arr.compressors) == want \
        and getattr(arr.metadata.chunk_key_encoding, "separator", None) == "."


def _root(where: str, mode: str) -> zarr.Group:
    try:
        return zarr.open_group(store=make_store(where, read_only=mode == "r"), mode=mode)
    except (zarr.errors.GroupNotFoundError, FileNotFoundError):
        raise LoomError("no photon store here", path=where) from None
