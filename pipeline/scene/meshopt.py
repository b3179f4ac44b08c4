"""meshoptimizer-compressed buffer views (``EXT_meshopt_compression``, what gltfpack writes),
decoded with the ``meshopt`` package's binding of meshoptimizer's own decoder (docs/16-libraries.md §5).

A compressed bufferView keeps its place for accessors and points its extension at compressed bytes
elsewhere (``buffer``, ``byteOffset``, ``byteLength``) with how they decode: ``count`` elements of
``byteStride`` bytes, ``mode`` ATTRIBUTES (vertex codec), TRIANGLES (index codec) or INDICES (index
sequence), and an optional ``filter`` (OCTAHEDRAL, QUATERNION, EXPONENTIAL, COLOR) undone after
decoding. The decoded bytes replace the view's own, which may live in a *fallback* buffer that
holds no data at all (the extension's ``fallback: true``); everything that reads accessors then
reads them as it reads uncompressed data. Spec: the extension's README in KhronosGroup/glTF.

Bounded by what the file holds: meshoptimizer's vertex codec reaches about 1,000 to 1 on rows of
zeros (measured: 1,022x at its level 3, 64x at the default level), so a view may claim at most
:data:`MAX_EXPANSION` times its compressed bytes, and never more than a buffer may hold.
"""
from __future__ import annotations

import meshopt
import numpy as np

from .gltf import MAX_BUFFER_BYTES, MESHOPT_EXTENSION, GltfDocument

EXTENSION = MESHOPT_EXTENSION
MODES = ("ATTRIBUTES", "TRIANGLES", "INDICES")
FILTERS = ("NONE", "OCTAHEDRAL", "QUATERNION", "EXPONENTIAL", "COLOR")
MAX_EXPANSION = 1024  # decoded bytes a compressed byte may claim: above the codec's best case
_SLACK = 1 << 16  # and a few blocks more, for tiny views


def decode_views(doc: GltfDocument) -> dict[int, bytes]:
    """bufferView index -> its decoded bytes, for every compressed view of ``doc``; a one-line
    error for a view whose data does not decode or claims more than its bytes can hold."""
    out = {}
    for i, view in enumerate(doc.gltf.bufferViews):
        ext = (view.extensions or {}).get(EXTENSION)
        if ext is not None:
            out[i] = _decode(doc, i, ext, f"bufferViews[{i}].extensions.{EXTENSION}")
    return out


def _decode(doc: GltfDocument, index: int, ext, where: str) -> bytes:
    if not isinstance(ext, dict):
        raise doc.error("must be an object", where)
    numbers = {}
    for name, lowest in (("buffer", 0), ("byteOffset", 0), ("byteLength", 1), ("byteStride", 1), ("count", 1)):
        value = ext.get(name, 0 if name == "byteOffset" else None)
        if not isinstance(value, int) or isinstance(value, bool) or value < lowest:
            raise doc.error(f"must be an integer of at least {lowest}, got {value!r}", f"{where}.{name}")
        numbers[name] = value
    mode, filt = ext.get("mode"), ext.get("filter", "NONE")
    if mode not in MODES:
        raise doc.error(f"{mode!r} is not one of {', '.join(MODES)}", f"{where}.mode")
    if filt not in FILTERS or (filt != "NONE" and mode != "ATTRIBUTES"):
        raise doc.error(f"{filt!r} is not a filter of {mode} data ({', '.join(FILTERS)})", f"{where}.filter")
    buffer, start, length = numbers["buffer"], numbers["byteOffset"], numbers["byteLength"]
    stride, count = numbers["byteStride"], numbers["count"]
    if buffer >= len(doc.buffers) or start + length > len(doc.buffers[buffer]):
        have = len(doc.buffers[buffer]) if buffer < len(doc.buffers) else None
        raise doc.error(f"bytes {start}..{start + length} of buffer {buffer} are not in the file "
                        f"({'no such buffer' if have is None else f'it has {have}'})", where)
    claimed = count * stride
    if claimed > min(MAX_BUFFER_BYTES, MAX_EXPANSION * length + _SLACK):
        raise doc.error(f"count {count} x byteStride {stride} claims {claimed:,} bytes from {length:,} compressed "
                        f"bytes, more than meshoptimizer's codec can expand them to", where)
    if mode == "ATTRIBUTES" and (stride > 256 or stride % 4):
        raise doc.error(f"byteStride {stride} of ATTRIBUTES must be a multiple of 4 up to 256", f"{where}.byteStride")
    if mode != "ATTRIBUTES" and stride not in (2, 4):
        raise doc.error(f"byteStride {stride} of {mode} must be 2 or 4", f"{where}.byteStride")
    view = doc.gltf.bufferViews[index]
    if view.byteLength is not None and view.byteLength != claimed:
        raise doc.error(f"decodes to {claimed:,} bytes, the view says byteLength {view.byteLength:,}", where)
    source = doc.buffers[buffer][start:start + length]
    try:
        rows = meshopt.decode_gltf_buffer(source, count, stride, mode, None if filt == "NONE" else filt)
    except ValueError as err:  # the decoder's own "Malformed buffer data", or a shape it refuses
        raise doc.error(f"the {length:,} bytes are not {mode} data that decode ({err})", where) from None
    return np.ascontiguousarray(rows).tobytes()
