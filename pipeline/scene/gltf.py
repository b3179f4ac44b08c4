"""Reading glTF 2.0 files: the container (``.glb`` or ``.gltf``), buffers and typed accessors.

pygltflib parses the JSON into its object model; the binary container, buffers and accessors are
read here so that every malformed input gets a one-line :class:`SceneError` naming the file and the
offending field (pygltflib itself would raise bare ``KeyError``/``struct.error``).
Spec: https://registry.khronos.org/glTF/specs/2.0/glTF-2.0.html (§4.4 "Binary glTF", §5.1 accessors).
"""
from __future__ import annotations

import base64
import hashlib
import json
import os
import stat
import struct
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import unquote, urlsplit

import numpy as np
import pygltflib

from ..errors import SceneError
from .gltf_schema import check_structure

GLB_MAGIC = 0x46546C67  # "glTF"
CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942

# The one table of glTF component types and accessor widths (spec §3.6.2.2, §5.1): the reader here,
# the writer of the built-in scenes (builtin/gltf_builder.py) and builtin/element_estimate.py use it.
COMPONENT_DTYPES = {
    5120: np.int8,
    5121: np.uint8,
    5122: np.int16,
    5123: np.uint16,
    5125: np.uint32,
    5126: np.float32,
}
TYPE_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}

# What a scene file may claim (docs/14-robustness.md §1). A buffer may not exceed a
# GLB's own uint32 length; an accessor without a bufferView is zeros that no byte backs, so its
# size is capped on its own (it is only meaningful with sparse data).
MAX_BUFFER_BYTES = (1 << 32) - 1
# Compressed buffer views (pipeline/scene/meshopt.py); a buffer marked as its fallback may hold no data
MESHOPT_EXTENSION = "EXT_meshopt_compression"
MAX_UNBACKED_ACCESSOR_BYTES = 1 << 28
# Buffer and image URIs must stay inside the scene's folder unless this is set to 1 (an explicit
# opt-in: a scene file should not read /etc/passwd or /dev/zero because it says so).
ALLOW_OUTSIDE_ENV = "PHOTONLOOM_ALLOW_OUTSIDE_FILES"

# Extensions we implement; anything else in ``extensionsRequired`` is refused. A file that requires
# KHR_animation_pointer is refused by the loader if it points at what is not animated (pointers.py).
SUPPORTED_REQUIRED_EXTENSIONS = frozenset(
    {"EXT_mesh_gpu_instancing", "KHR_animation_pointer", "KHR_draco_mesh_compression", "KHR_lights_punctual",
     "KHR_materials_emissive_strength", "KHR_materials_ior", "KHR_materials_transmission",
     "KHR_materials_volume", "KHR_mesh_quantization", "EXT_meshopt_compression", "KHR_texture_basisu",
     "KHR_materials_variants",
     "KHR_node_visibility", "KHR_texture_transform", "EXT_texture_webp"}
)


@dataclass
class GltfDocument:
    """A parsed glTF file: the pygltflib object model plus its loaded buffers."""

    path: Path
    gltf: pygltflib.GLTF2
    buffers: list[bytes]
    digest: str  # sha256 of the JSON text and every buffer: identifies the scene content
    tree: dict = field(default_factory=dict, repr=False)  # the parsed JSON, for what pygltflib drops (node.weights)
    # accessor -> its values decoded from compressed data (pipeline/scene/draco.py), read in place of its bytes
    decoded: dict[int, np.ndarray] = field(default_factory=dict, repr=False)
    # bufferView -> its bytes decoded from compressed data (pipeline/scene/meshopt.py), read in place of its own
    views: dict[int, bytes] = field(default_factory=dict, repr=False)

    def error(self, message: str, field: str | None = None) -> SceneError:
        return SceneError(message, path=str(self.path), field=field)

    def accessor(self, index: int, field: str, *, types: tuple[str, ...] | None = None,
                 components: tuple[int, ...] | None = None) -> np.ndarray:
        """Accessor ``index`` as an array of shape (count,) or (count, width), bounds-checked.

        Normalized integer accessors are mapped to [0, 1] or [-1, 1] as the spec's
        "normalized" rules (§3.11) say. Sparse accessors (§3.6.2.3, exporters write morph targets
        so) replace the listed elements of the base (its bufferView, or zeros). ``types`` and
        ``components`` restrict what the use allows (indices: unsigned SCALAR). Every size is
        checked against the bytes that back it before anything is allocated.
        """
        g = self.gltf
        where = f"{field} -> accessors[{index}]"
        if not _is_int(index) or not 0 <= index < len(g.accessors):
            raise self.error(f"refers to a missing accessor {index}", field)
        acc = g.accessors[index]
        dtype = COMPONENT_DTYPES.get(acc.componentType) if _is_int(acc.componentType) else None
        width = TYPE_WIDTH.get(acc.type) if isinstance(acc.type, str) else None
        if dtype is None or width is None:
            raise self.error(f"unknown componentType {acc.componentType} or type {acc.type!r}", where)
        if types is not None and acc.type not in types:
            raise self.error(f"type {acc.type} is not allowed here ({', '.join(types)})", where)
        if components is not None and acc.componentType not in components:
            raise self.error(f"componentType {acc.componentType} is not allowed here "
                             f"({', '.join(map(str, components))})", where)
        count = _integer(acc.count, 1, self, where + ".count")
        offset = _integer(acc.byteOffset, 0, self, where + ".byteOffset", default=0)
        itemsize = np.dtype(dtype).itemsize
        if offset % itemsize:
            raise self.error(f"byteOffset {offset} is not a multiple of the component size {itemsize}", where)
        if index in self.decoded:
            out = self.decoded[index]
        elif acc.bufferView is None:  # all zeros, per spec: nothing backs them, so they are capped
            if count * width * itemsize > MAX_UNBACKED_ACCESSOR_BYTES:
                raise self.error(f"count {count} claims {count * width * itemsize:,} bytes of zeros without a "
                                 f"bufferView, more than {MAX_UNBACKED_ACCESSOR_BYTES:,}", where)
            out = np.zeros((count, width), dtype=dtype)
        else:
            out = self._read_view(acc.bufferView, offset, dtype, width, count, where)
        if acc.sparse is not None:
            self._substitute_sparse(acc.sparse, out, dtype, width, where + ".sparse")
        if acc.normalized and np.issubdtype(out.dtype, np.integer):
            info = np.iinfo(dtype)
            out = np.maximum(out.astype(np.float64) / info.max, -1.0)
        return out[:, 0] if width == 1 else out

    def view_bytes(self, view_index: int, where: str) -> np.ndarray:
        """The bytes of bufferView ``view_index`` (uint8), bounds-checked like an accessor's."""
        length = _integer(self.gltf.bufferViews[view_index].byteLength, 1, self,
                          f"bufferViews[{view_index}].byteLength")
        return self._read_view(view_index, 0, np.uint8, 1, length, where)[:, 0]

    def _substitute_sparse(self, sparse, out: np.ndarray, dtype, width: int, where: str) -> None:
        """Write a sparse accessor's values over ``out`` (count, width) at its indices (glTF 2.0
        §3.6.2.3: strictly increasing unsigned indices below the accessor's count)."""
        def get(obj, name):
            return obj.get(name) if isinstance(obj, dict) else getattr(obj, name, None)

        n = _integer(get(sparse, "count"), 1, self, where + ".count")
        if n > len(out):
            raise self.error(f"count {n} exceeds the accessor's {len(out)} elements", where + ".count")
        indices, values = get(sparse, "indices"), get(sparse, "values")
        if indices is None or values is None:
            raise self.error("needs indices and values", where)
        component = get(indices, "componentType")
        if component not in (5121, 5123, 5125):
            raise self.error(f"componentType {component} must be an unsigned byte, short or int",
                             where + ".indices.componentType")
        offset = _integer(get(indices, "byteOffset"), 0, self, where + ".indices.byteOffset", default=0)
        idx = self._read_view(get(indices, "bufferView"), offset, COMPONENT_DTYPES[component], 1, n,
                              where + ".indices")[:, 0].astype(np.int64)
        if np.any(np.diff(idx) <= 0) or idx[-1] >= len(out):
            raise self.error(f"indices must increase strictly and stay below {len(out)}", where + ".indices")
        offset = _integer(get(values, "byteOffset"), 0, self, where + ".values.byteOffset", default=0)
        out[idx] = self._read_view(get(values, "bufferView"), offset, dtype, width, n, where + ".values")

    def _read_view(self, view_index, offset, dtype, width, count, where) -> np.ndarray:
        g = self.gltf
        if not _is_int(view_index) or not 0 <= view_index < len(g.bufferViews):
            raise self.error(f"refers to a missing bufferView {view_index}", where)
        view = g.bufferViews[view_index]
        vf = f"bufferViews[{view_index}]"
        if not _is_int(view.buffer) or not 0 <= view.buffer < len(self.buffers):
            raise self.error(f"{vf} refers to a missing buffer {view.buffer}", where)
        data = self.buffers[view.buffer]
        itemsize = np.dtype(dtype).itemsize
        elem_bytes = itemsize * width
        view_start = _integer(view.byteOffset, 0, self, vf + ".byteOffset", default=0)
        view_len = _integer(view.byteLength, 1, self, vf + ".byteLength")
        if view_index in self.views:  # decoded from compressed bytes: the view is all of them
            data, view_start, view_len = self.views[view_index], 0, len(self.views[view_index])
        stride = elem_bytes
        if view.byteStride is not None:  # glTF §3.6.2.4: 4..252, a multiple of 4, at least one element
            stride = _integer(view.byteStride, 4, self, vf + ".byteStride")
            if stride > 252 or stride % 4:
                raise self.error(f"byteStride {stride} must be a multiple of 4 in [4, 252]", vf + ".byteStride")
            if stride < elem_bytes:
                raise self.error(f"byteStride {stride} is smaller than the {elem_bytes}-byte element of {where}",
                                 vf + ".byteStride")
        if (view_start + offset) % itemsize:
            raise self.error(f"starts at buffer byte {view_start + offset}, not a multiple of the component "
                             f"size {itemsize}", where)
        if view_start + view_len > len(data):
            raise self.error(
                f"{vf} spans bytes {view_start}..{view_start + view_len} "
                f"but buffer {view.buffer} has {len(data)}",
                where,
            )
        needed = offset + stride * (count - 1) + elem_bytes
        if needed > view_len:
            raise self.error(
                f"out of range: needs {needed} bytes of {vf}, which has {view_len}",
                where,
            )
        start = view_start + offset
        if stride == elem_bytes:
            flat = np.frombuffer(data, dtype=dtype, count=count * width, offset=start)
            return flat.reshape(count, width).copy()
        rows = np.ndarray(
            shape=(count, width), dtype=dtype, buffer=data, offset=start, strides=(stride, itemsize)
        )
        return rows.copy()


def _is_int(value) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def _integer(value, minimum: int, doc: GltfDocument, field: str, default: int | None = None) -> int:
    """A glTF integer property at least ``minimum`` (absent: ``default``, or an error without one)."""
    if value is None and default is not None:
        return default
    if not _is_int(value):
        raise doc.error(f"must be an integer, got {value!r}", field)
    if value < minimum:
        raise doc.error(f"must be at least {minimum}, got {value}", field)
    return int(value)


def read_gltf(path: str | Path) -> GltfDocument:
    """Load a ``.glb`` or ``.gltf`` file (external or data-URI buffers) with its buffers."""
    path = Path(path)
    raw = _read_regular(path, MAX_BUFFER_BYTES, path=str(path), field=None)

    bin_chunk = None
    if raw[:4] == b"glTF":
        json_bytes, bin_chunk = _split_glb(raw, path)
    elif path.suffix.lower() == ".glb":
        raise SceneError(f"not a binary glTF: wrong magic {raw[:4]!r}", path=str(path), field="header")
    else:
        json_bytes = raw
    try:
        text = json_bytes.decode("utf-8")
        tree = json.loads(text)  # pygltflib swallows some errors; validate strictly first
    except (UnicodeDecodeError, ValueError, RecursionError) as err:
        raise SceneError(f"broken JSON: {err}", path=str(path), field="json") from None
    check_structure(tree, str(path))
    try:
        gltf = pygltflib.GLTF2.from_json(text)
    except Exception as err:  # pygltflib's schema mapping (wrong types for fields)
        raise SceneError(f"malformed glTF JSON: {err}", path=str(path), field="json") from None

    version = getattr(gltf.asset, "version", None) if gltf.asset else None
    if not version or not str(version).startswith("2."):
        raise SceneError(f"asset.version {version!r} is not glTF 2.x", path=str(path), field="asset.version")
    unsupported = sorted(set(gltf.extensionsRequired or []) - SUPPORTED_REQUIRED_EXTENSIONS)
    if unsupported:
        raise SceneError(
            f"requires unsupported extension(s) {', '.join(unsupported)}",
            path=str(path),
            field="extensionsRequired",
        )

    for i, image in enumerate(gltf.images):  # read by nobody here, but a scene may not point outside
        if isinstance(image.uri, str) and not image.uri.startswith("data:"):
            scene_file(path, image.uri, f"images[{i}].uri")
    buffers = [_load_buffer(gltf, i, path, bin_chunk) for i in range(len(gltf.buffers))]
    digest = hashlib.sha256(json_bytes)
    for buf in buffers:
        digest.update(hashlib.sha256(buf).digest())
    return GltfDocument(path=path, gltf=gltf, buffers=buffers, digest=digest.hexdigest(), tree=tree)


def _split_glb(raw: bytes, path: Path) -> tuple[bytes, bytes | None]:
    """Split a GLB container into its JSON and BIN chunks (spec §4.4), checking every length."""
    p = str(path)
    if len(raw) < 20:
        raise SceneError(f"truncated: {len(raw)} bytes, shorter than a GLB header", path=p, field="header")
    magic, version, length = struct.unpack_from("<III", raw, 0)
    if magic != GLB_MAGIC:
        raise SceneError("not a binary glTF: wrong magic", path=p, field="header")
    if version != 2:
        raise SceneError(f"GLB container version {version}, expected 2", path=p, field="header")
    if length > len(raw):
        raise SceneError(f"truncated: header says {length} bytes, file has {len(raw)}", path=p, field="header")
    chunks = []
    pos = 12
    while pos < length:
        if pos + 8 > length:
            raise SceneError(f"truncated chunk header at byte {pos}", path=p, field="chunks")
        clen, ctype = struct.unpack_from("<II", raw, pos)
        if pos + 8 + clen > length:
            raise SceneError(
                f"truncated: chunk at byte {pos} needs {clen} bytes, {length - pos - 8} remain",
                path=p,
                field="chunks",
            )
        chunks.append((ctype, raw[pos + 8 : pos + 8 + clen]))
        pos += 8 + clen
    if not chunks or chunks[0][0] != CHUNK_JSON:
        raise SceneError("first chunk is not JSON", path=p, field="chunks")
    bin_chunk = chunks[1][1] if len(chunks) > 1 and chunks[1][0] == CHUNK_BIN else None
    return chunks[0][1], bin_chunk


def _load_buffer(gltf: pygltflib.GLTF2, index: int, path: Path, bin_chunk: bytes | None) -> bytes:
    buf = gltf.buffers[index]
    field = f"buffers[{index}]"
    p = str(path)
    uri = buf.uri
    fallback = (buf.extensions or {}).get(MESHOPT_EXTENSION)
    if uri is None and isinstance(fallback, dict) and fallback.get("fallback") is True:
        return b""  # holds nothing: its views are all compressed elsewhere (pipeline/scene/meshopt.py)
    if uri is None:
        if index != 0 or bin_chunk is None:
            raise SceneError("has no uri and there is no GLB binary chunk", path=p, field=field)
        data = bin_chunk
    elif uri.startswith("data:"):
        if len(uri) > MAX_BUFFER_BYTES * 4 // 3 + 100:
            raise SceneError(f"data URI is longer than a {MAX_BUFFER_BYTES:,}-byte buffer", path=p, field=field)
        header, _, payload = uri.partition(",")
        if not header.endswith(";base64"):
            raise SceneError("data URI is not base64", path=p, field=field)
        try:
            data = base64.b64decode(payload, validate=True)
        except ValueError as err:
            raise SceneError(f"bad base64 data URI: {err}", path=p, field=field) from None
    else:
        data = _read_regular(scene_file(path, uri, field + ".uri"), MAX_BUFFER_BYTES, path=p, field=field,
                             what=f"buffer file {uri!r}")
    need = int(buf.byteLength or 0)
    if need < 1:
        raise SceneError(f"byteLength must be at least 1, got {buf.byteLength!r}", path=p, field=field)
    if len(data) < need:
        raise SceneError(f"byteLength is {need} but only {len(data)} bytes are present", path=p, field=field)
    return data


def scene_file(scene: Path, uri: str, field: str) -> Path:
    """The file a relative ``uri`` of ``scene`` names (percent-decoded, glTF §3.3), refused when it
    is absolute, has a scheme or leads outside the scene's folder (symbolic links resolved), unless
    ``PHOTONLOOM_ALLOW_OUTSIDE_FILES=1`` allows it explicitly."""
    p = str(scene)
    parts = urlsplit(uri)
    if parts.scheme and len(parts.scheme) > 1:  # "C:" is a Windows drive, not a scheme
        raise SceneError(f"URI {uri!r}: only relative file paths and data: URIs are read", path=p, field=field)
    relative = unquote(uri)
    folder = scene.parent.resolve()
    target = (folder / relative).resolve()
    if os.environ.get(ALLOW_OUTSIDE_ENV) == "1":
        return target
    if Path(relative).is_absolute() or not target.is_relative_to(folder):
        raise SceneError(f"URI {uri!r} leads outside the scene's folder {folder} (set {ALLOW_OUTSIDE_ENV}=1 "
                         "to allow it)", path=p, field=field)
    return target


def _read_regular(target: Path, limit: int, *, path: str, field: str | None, what: str = "the file") -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes: a device (/dev/zero), pipe or folder
    would never end or is not data, so it is refused before it is opened."""
    try:
        st = target.stat()
    except FileNotFoundError:
        raise SceneError(f"missing {what}" if field else "no such file", path=path, field=field) from None
    except OSError as err:
        raise SceneError(f"cannot read {what}: {err.strerror}", path=path, field=field) from None
    if not stat.S_ISREG(st.st_mode):
        raise SceneError(f"{what} is not a regular file (a device, pipe or folder)", path=path, field=field)
    if st.st_size > limit:
        raise SceneError(f"{what} has {st.st_size:,} bytes, more than {limit:,}", path=path, field=field)
    try:
        return target.read_bytes()
    except OSError as err:
        raise SceneError(f"cannot read {what}: {err.strerror}", path=path, field=field) from None
