"""meshoptimizer-compressed copies of glTF files for the tests, as gltfpack writes them
(EXT_meshopt_compression): every bufferView encoded by the ``meshopt`` package into one buffer of
compressed bytes (triangle indices with the index codec, which may rotate a triangle's corners but
keeps its winding; everything else as rows of its byteStride, or of 4 bytes, with the vertex codec),
the views themselves moved to a fallback buffer that holds nothing."""
from __future__ import annotations

import base64
import json
from pathlib import Path

import meshopt
import numpy as np

from pipeline.scene.gltf import COMPONENT_DTYPES, read_gltf

EXTENSION = "EXT_meshopt_compression"


def _uri(data: bytes) -> str:
    return "data:application/octet-stream;base64," + base64.b64encode(data).decode()


def compress(src: str | Path, dst: str | Path) -> Path:
    """Write ``dst`` (.gltf, embedded buffers), a copy of ``src`` whose buffer views are meshopt-compressed."""
    doc = read_gltf(src)
    tree = json.loads(json.dumps(doc.tree))
    index_views = {tree["accessors"][p["indices"]]["bufferView"]: tree["accessors"][p["indices"]]["componentType"]
                   for m in tree["meshes"] for p in m["primitives"] if "indices" in p}
    packed = bytearray()
    fallback = len(tree["buffers"])
    for v, view in enumerate(tree["bufferViews"]):
        start, length = view.get("byteOffset", 0), view["byteLength"]
        raw = doc.buffers[view["buffer"]][start:start + length]
        if v in index_views:
            dtype = np.dtype(COMPONENT_DTYPES[index_views[v]])
            mode, stride = "TRIANGLES", dtype.itemsize
            data = np.frombuffer(raw, dtype).astype(np.uint32)
        else:
            mode, stride = "ATTRIBUTES", view.get("byteStride", 4)
            data = np.frombuffer(raw, np.uint32).reshape(-1, stride // 4)
        encoded = meshopt.encode_gltf_buffer(data, mode)
        while len(packed) % 4:
            packed.append(0)
        view["extensions"] = {EXTENSION: {"buffer": fallback + 1, "byteOffset": len(packed),
                                          "byteLength": len(encoded), "byteStride": stride,
                                          "count": length // stride, "mode": mode}}
        view["buffer"] = fallback
        packed += encoded
    tree["buffers"] = [{"byteLength": len(b), "uri": _uri(b)} for b in doc.buffers]
    size = max(v.get("byteOffset", 0) + v["byteLength"] for v in tree["bufferViews"])
    tree["buffers"].append({"byteLength": size, "extensions": {EXTENSION: {"fallback": True}}})
    tree["buffers"].append({"byteLength": len(packed), "uri": _uri(bytes(packed))})
    for key in ("extensionsUsed", "extensionsRequired"):
        tree[key] = sorted(set(tree.get(key, [])) | {EXTENSION})
    Path(dst).write_text(json.dumps(tree))
    return Path(dst)
