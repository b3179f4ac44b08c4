"""Draco-compressed primitives (``KHR_draco_mesh_compression``), decoded with DracoPy, Google's
Draco decoder (docs/16-libraries.md §4).

A compressed primitive keeps its accessors (count, type, component type) and points its
extension at a bufferView of Draco data whose attributes, by unique id, hold the values of the
primitive's named attributes (the extension's specification: "Conformance", "Restrictions on
geometry type"). The decoded values replace what those accessors (and the indices accessor) would
read, so everything that reads accessors (positions, normals, texture coordinates, colours, skin
joints and weights) takes them as it takes uncompressed data; morph targets stay uncompressed,
in the decoded vertex order, as the specification requires of encoders.
"""
from __future__ import annotations

import DracoPy
import numpy as np

from .gltf import COMPONENT_DTYPES, TYPE_WIDTH, GltfDocument

EXTENSION = "KHR_draco_mesh_compression"


def decode_primitives(doc: GltfDocument) -> dict[int, np.ndarray]:
    """accessor index -> its values (count, width) decoded from the Draco data of every compressed
    primitive of ``doc``; a one-line error for data that does not decode or does not match the
    accessors that describe it."""
    decoded: dict[int, np.ndarray] = {}
    raw_meshes = doc.tree.get("meshes", [])
    for m, mesh in enumerate(doc.gltf.meshes):
        for p, prim in enumerate(mesh.primitives):
            ext = (prim.extensions or {}).get(EXTENSION)
            if ext is None:
                continue
            where = f"meshes[{m}].primitives[{p}].extensions.{EXTENSION}"
            attributes = raw_meshes[m]["primitives"][p].get("attributes", {})
            for index, values in _decode(doc, prim, ext, attributes, where).items():
                if index in decoded and not np.array_equal(decoded[index], values):
                    raise doc.error(f"accessor {index} is decoded from two primitives' Draco data that differ", where)
                decoded[index] = values
    return decoded


def _decode(doc: GltfDocument, prim, ext, attributes: dict, where: str) -> dict[int, np.ndarray]:
    if not isinstance(ext, dict) or not isinstance(ext.get("attributes"), dict):
        raise doc.error("needs a bufferView and an attributes map", where)
    if (prim.mode if prim.mode is not None else 4) != 4:
        raise doc.error(f"mode {prim.mode}: Draco primitives here are TRIANGLES", where)
    view = ext.get("bufferView")
    g = doc.gltf
    if not isinstance(view, int) or isinstance(view, bool) or not 0 <= view < len(g.bufferViews):
        raise doc.error(f"refers to a missing bufferView {view!r}", where + ".bufferView")
    length = g.bufferViews[view].byteLength
    data = doc.view_bytes(view, where + ".bufferView")
    try:
        mesh = DracoPy.decode(data.tobytes())
    except Exception as err:  # DracoPy raises its own failures for a stream that is not Draco
        raise doc.error(f"the {length:,} bytes of bufferView {view} are not Draco data that decode "
                        f"({type(err).__name__}: {err})", where + ".bufferView") from None
    faces = np.asarray(getattr(mesh, "faces", None) if isinstance(mesh, DracoPy.DracoMesh) else None)
    if faces is None or faces.ndim != 2 or faces.shape[1:] != (3,) or not len(faces):
        raise doc.error("the Draco data hold no triangles (a point cloud)", where + ".bufferView")
    points = getattr(mesh, "points", None)
    if points is None or not len(points):  # what Draco makes of a stream whose counts its bytes cannot hold
        raise doc.error(f"the {length:,} bytes of bufferView {view} are not Draco data that decode (no points)",
                        where + ".bufferView")
    n_points = len(points)
    out: dict[int, np.ndarray] = {}
    for semantic, uid in ext["attributes"].items():
        field = where + f".attributes.{semantic}"
        accessor = attributes.get(semantic)
        if accessor is None:
            raise doc.error(f"compresses {semantic}, which the primitive's attributes do not name", field)
        found = mesh.get_attribute_by_unique_id(uid) if isinstance(uid, int) else None
        if found is None:
            raise doc.error(f"the Draco data have no attribute with unique id {uid!r}", field)
        out[accessor] = _as_accessor(doc, accessor, np.asarray(found["data"]).reshape(n_points, -1), field)
    if prim.indices is not None:
        out[prim.indices] = _as_accessor(doc, prim.indices, faces.reshape(-1, 1), where + " (indices)")
    return out


def _as_accessor(doc: GltfDocument, index: int, values: np.ndarray, where: str) -> np.ndarray:
    """``values`` checked against accessor ``index``'s count and width and given its component
    type: decoded integers become the accessor's (normalized by the reader), floats stay floats."""
    if not isinstance(index, int) or not 0 <= index < len(doc.gltf.accessors):
        raise doc.error(f"refers to a missing accessor {index}", where)
    acc = doc.gltf.accessors[index]
    width, dtype = TYPE_WIDTH.get(acc.type), COMPONENT_DTYPES.get(acc.componentType)
    if values.shape != (acc.count, width):
        raise doc.error(f"the Draco data decode to {values.shape[0]:,} x {values.shape[1]} values, accessor "
                        f"{index} describes {acc.count:,} x {width}", where)
    if dtype is None or not np.issubdtype(values.dtype, np.integer) or not np.issubdtype(dtype, np.integer):
        return values.astype(np.float32) if not np.issubdtype(values.dtype, np.integer) else values
    info = np.iinfo(dtype)
    if values.size and (values.min() < info.min or values.max() > info.max):
        raise doc.error(f"decoded values {values.min()}..{values.max()} do not fit accessor {index}'s "
                        f"component type {acc.componentType}", where)
    return values.astype(dtype)
