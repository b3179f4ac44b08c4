"""Draco-compressed copies of glTF files for the tests, as glTF-Transform and Blender's exporter
write them (KHR_draco_mesh_compression): each primitive's attributes and indices encoded by
DracoPy into one bufferView, their accessors left without a bufferView, the extension required."""
from __future__ import annotations

import base64
import json
from pathlib import Path

import DracoPy
import numpy as np

from pipeline.scene.gltf import read_gltf

EXTENSION = "KHR_draco_mesh_compression"
# Draco's own attributes: DracoPy's encode arguments; the rest (colours, skin joints and weights) are generic
_NAMED = {"NORMAL": "normals", "TEXCOORD_0": "tex_coord"}


def compress(src: str | Path, dst: str | Path, *, quantization_bits: int = 14, generic_start: int = 10) -> Path:
    """Write ``dst`` (.gltf, one embedded buffer), a copy of ``src`` whose primitives are
    Draco-compressed; vertex order is preserved, so uncompressed morph targets still apply."""
    doc = read_gltf(src)
    tree = json.loads(json.dumps(doc.tree))
    blob = bytearray(b"".join(doc.buffers[:1]))
    others = doc.buffers[1:]
    for mesh in tree["meshes"]:
        for prim in mesh["primitives"]:
            attrs = prim["attributes"]
            points = np.asarray(doc.accessor(attrs["POSITION"], "POSITION"), np.float32)
            faces = np.asarray(doc.accessor(prim["indices"], "indices")).reshape(-1, 3).astype(np.uint32)
            named = {arg: np.asarray(doc.accessor(attrs[sem], sem), np.float64)
                     for sem, arg in _NAMED.items() if sem in attrs}
            generic = {generic_start + i: doc.accessor(attrs[sem], sem) for i, sem in enumerate(sorted(attrs))
                       if sem != "POSITION" and sem not in _NAMED}
            data = DracoPy.encode(points, faces, quantization_bits=quantization_bits, preserve_order=True,
                                  generic_attributes=generic or None, **named)
            decoded = DracoPy.decode(data)
            ids = {a["attribute_type"]: a["unique_id"] for a in decoded.attributes if a["attribute_type"] != 4}
            uid = {"POSITION": ids[0], "NORMAL": ids.get(1), "TEXCOORD_0": ids.get(3)}
            uid.update({sem: key for key, sem in zip(generic, [s for s in sorted(attrs) if s != "POSITION"
                                                                and s not in _NAMED])})
            while len(blob) % 4:
                blob.append(0)
            tree["bufferViews"].append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)})
            blob += data
            prim.setdefault("extensions", {})[EXTENSION] = {
                "bufferView": len(tree["bufferViews"]) - 1, "attributes": {sem: uid[sem] for sem in attrs}}
            for index in [*attrs.values(), prim["indices"]]:
                tree["accessors"][index].pop("bufferView", None)
                tree["accessors"][index].pop("byteOffset", None)
    buffers = [bytes(blob), *others]
    tree["buffers"] = [{"byteLength": len(b), "uri": "data:application/octet-stream;base64,"
                        + base64.b64encode(b).decode()} for b in buffers]
    for key in ("extensionsUsed", "extensionsRequired"):
        tree[key] = sorted(set(tree.get(key, [])) | {EXTENSION})
    Path(dst).write_text(json.dumps(tree))
    return Path(dst)
