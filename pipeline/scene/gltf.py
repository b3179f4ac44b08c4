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
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pygltflib

from ..errors import SceneError

GLB_MAGIC = 0x46546C67  # "glTF"
CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942

_COMPONENT_DTYPES = {
    5120: np.int8,
    5121: np.uint8,
    5122: np.int16,
    5123: np.uint16,
    5125: np.uint32,
    5126: np.float32,
}
_TYPE_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}

# Extensions we implement; anything else in ``extensionsRequired`` is refused.
SUPPORTED_REQUIRED_EXTENSIONS = frozenset(
    {"KHR_lights_punctual", "KHR_materials_emissive_strength", "KHR_mesh_quantization",
     "KHR_texture_transform"}
)


@dataclass
class GltfDocument:
    """A parsed glTF file: the pygltflib object model plus its loaded buffers."""

    path: Path
    gltf: pygltflib.GLTF2
    buffers: list[bytes]
    digest: str  # sha256 of the JSON text and every buffer: identifies the scene content

    def error(self, message: str, field: str | None = None) -> SceneError:
        return SceneError(message, path=str(self.path), field=field)

    def accessor(self, index: int, field: str) -> np.ndarray:
        """Accessor ``index`` as an array of shape (count,) or (count, width), bounds-checked.

        Normalized integer accessors are mapped to [0, 1] or [-1, 1] as the spec's
        "normalized" rules (§3.11) say. Sparse accessors are refused.
        """
        g = self.gltf
        where = f"{field} -> accessors[{index}]"
        if index is None or not 0 <= index < len(g.accessors):
            raise self.error(f"refers to a missing accessor {index}", field)
        acc = g.accessors[index]
        if acc.sparse is not None:
            raise self.error("sparse accessors are not supported", where)
        dtype = _COMPONENT_DTYPES.get(acc.componentType)
        width = _TYPE_WIDTH.get(acc.type)
        if dtype is None or width is None:
            raise self.error(f"unknown componentType {acc.componentType} or type {acc.type!r}", where)
        count = int(acc.count or 0)
        if count <= 0:
            raise self.error("count must be positive", where)
        if acc.bufferView is None:  # all zeros, per spec
            out = np.zeros((count, width), dtype=dtype)
        else:
            out = self._read_view(acc.bufferView, int(acc.byteOffset or 0), dtype, width, count, where)
        if acc.normalized and np.issubdtype(dtype, np.integer):
            info = np.iinfo(dtype)
            out = np.maximum(out.astype(np.float64) / info.max, -1.0)
        return out[:, 0] if width == 1 else out

    def _read_view(self, view_index, offset, dtype, width, count, where) -> np.ndarray:
        g = self.gltf
        if not 0 <= view_index < len(g.bufferViews):
            raise self.error(f"refers to a missing bufferView {view_index}", where)
        view = g.bufferViews[view_index]
        if view.buffer is None or not 0 <= view.buffer < len(self.buffers):
            raise self.error(f"bufferViews[{view_index}] refers to a missing buffer {view.buffer}", where)
        data = self.buffers[view.buffer]
        itemsize = np.dtype(dtype).itemsize
        elem_bytes = itemsize * width
        stride = int(view.byteStride or elem_bytes)
        view_start = int(view.byteOffset or 0)
        view_len = int(view.byteLength or 0)
        if view_start + view_len > len(data):
            raise self.error(
                f"bufferViews[{view_index}] spans bytes {view_start}..{view_start + view_len} "
                f"but buffer {view.buffer} has {len(data)}",
                where,
            )
        needed = offset + stride * (count - 1) + elem_bytes
        if needed > view_len:
            raise self.error(
                f"out of range: needs {needed} bytes of bufferViews[{view_index}], which has {view_len}",
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


def read_gltf(path: str | Path) -> GltfDocument:
    """Load a ``.glb`` or ``.gltf`` file (external or data-URI buffers) with its buffers."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise SceneError("no such file", path=str(path)) from None
    except OSError as err:
        raise SceneError(f"cannot read: {err.strerror}", path=str(path)) from None

    bin_chunk = None
    if raw[:4] == b"glTF":
        json_bytes, bin_chunk = _split_glb(raw, path)
    elif path.suffix.lower() == ".glb":
        raise SceneError(f"not a binary glTF: wrong magic {raw[:4]!r}", path=str(path), field="header")
    else:
        json_bytes = raw
    try:
        text = json_bytes.decode("utf-8")
        json.loads(text)  # pygltflib swallows some errors; validate strictly first
        gltf = pygltflib.GLTF2.from_json(text)
    except (UnicodeDecodeError, ValueError) as err:
        raise SceneError(f"broken JSON: {err}", path=str(path), field="json") from None
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

    buffers = [_load_buffer(gltf, i, path, bin_chunk) for i in range(len(gltf.buffers))]
    digest = hashlib.sha256(json_bytes)
    for buf in buffers:
        digest.update(hashlib.sha256(buf).digest())
    return GltfDocument(path=path, gltf=gltf, buffers=buffers, digest=digest.hexdigest())


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
    if uri is None:
        if index != 0 or bin_chunk is None:
            raise SceneError("has no uri and there is no GLB binary chunk", path=p, field=field)
        data = bin_chunk
    elif uri.startswith("data:"):
        header, _, payload = uri.partition(",")
        if not header.endswith(";base64"):
            raise SceneError("data URI is not base64", path=p, field=field)
        try:
            data = base64.b64decode(payload, validate=True)
        except ValueError as err:
            raise SceneError(f"bad base64 data URI: {err}", path=p, field=field) from None
    else:
        from urllib.parse import unquote

        target = path.parent / unquote(uri)
        try:
            data = target.read_bytes()
        except OSError:
            raise SceneError(f"missing buffer file {uri!r}", path=p, field=field) from None
    need = int(buf.byteLength or 0)
    if len(data) < need:
        raise SceneError(f"byteLength is {need} but only {len(data)} bytes are present", path=p, field=field)
    return data
