"""The JSON shape of the glTF properties we read, checked before pygltflib maps them to objects.

pygltflib takes any JSON value for any property, so a string where an index belongs or an array
where an object belongs would surface later as a Python TypeError or AttributeError. Checking the
shape first, from the types glTF 2.0's JSON schema gives each property
(https://registry.khronos.org/glTF/specs/2.0/glTF-2.0.html §5), turns every such file into one
line naming the property: ``nodes[3].children[0]: must be a non-negative integer, got "2"``.
Only properties photonloom reads are listed; anything else (extras, unknown extensions) passes.
"""
from __future__ import annotations

import math

from ..errors import SceneError

INDEX = "a non-negative integer"  # indices, counts, byte offsets and lengths
INT = "an integer"
NUM = "a finite number"
STR = "a string"
BOOL = "true or false"
OBJ = "an object"


def _list(item):
    return ("list", item)


def _map(item):  # an object whose every value has the shape ``item`` (attributes, targets)
    return ("map", item)


_NUMS = _list(NUM)
_LIGHTS_PUNCTUAL = {"lights": _list({"type": STR, "name": STR, "color": _NUMS, "intensity": NUM, "range": NUM,
                                     "spot": {"innerConeAngle": NUM, "outerConeAngle": NUM}})}
SCHEMA = {
    "asset": {"version": STR},
    "extensionsRequired": _list(STR),
    "extensionsUsed": _list(STR),
    "extensions": {"KHR_lights_punctual": _LIGHTS_PUNCTUAL},
    "scene": INDEX,
    "scenes": _list({"nodes": _list(INDEX), "name": STR}),
    "nodes": _list({"name": STR, "children": _list(INDEX), "mesh": INDEX, "camera": INDEX, "skin": INDEX,
                    "matrix": _NUMS, "translation": _NUMS, "rotation": _NUMS, "scale": _NUMS, "weights": _NUMS,
                    "extensions": {"KHR_lights_punctual": {"light": INDEX}, "KHR_node_visibility": {"visible": BOOL}}}),
    "meshes": _list({"name": STR, "weights": _NUMS,
                     "primitives": _list({"attributes": _map(INDEX), "indices": INDEX, "material": INDEX,
                                          "mode": INDEX, "targets": _list(_map(INDEX))})}),
    "accessors": _list({"bufferView": INDEX, "byteOffset": INDEX, "componentType": INT, "count": INDEX,
                        "type": STR, "normalized": BOOL, "min": _NUMS, "max": _NUMS, "sparse": OBJ}),
    "bufferViews": _list({"buffer": INDEX, "byteOffset": INDEX, "byteLength": INDEX, "byteStride": INDEX,
                          "target": INT}),
    "buffers": _list({"uri": STR, "byteLength": INDEX}),
    "images": _list({"uri": STR, "mimeType": STR, "bufferView": INDEX}),
    "textures": _list({"source": INDEX, "sampler": INDEX}),
    "animations": _list({"name": STR,
                         "channels": _list({"sampler": INDEX, "target": {"node": INDEX, "path": STR}}),
                         "samplers": _list({"input": INDEX, "output": INDEX, "interpolation": STR})}),
    "cameras": _list({"name": STR, "type": STR, "perspective": {"yfov": NUM, "znear": NUM, "zfar": NUM,
                                                               "aspectRatio": NUM},
                               "orthographic": {"xmag": NUM, "ymag": NUM, "znear": NUM, "zfar": NUM}}),
    "materials": _list({"name": STR, "emissiveFactor": _NUMS, "doubleSided": BOOL, "alphaMode": STR,
                        "pbrMetallicRoughness": {"baseColorFactor": _NUMS, "metallicFactor": NUM,
                                                 "roughnessFactor": NUM, "baseColorTexture": {"index": INDEX}},
                        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": NUM},
                                       "KHR_materials_transmission": {"transmissionFactor": NUM,
                                                                      "transmissionTexture": {"index": INDEX}},
                                       "KHR_materials_ior": {"ior": NUM},
                                       "KHR_materials_volume": {"thicknessFactor": NUM, "attenuationDistance": NUM,
                                                                "attenuationColor": _NUMS}}}),
    "skins": _list({"joints": _list(INDEX), "inverseBindMatrices": INDEX, "skeleton": INDEX}),
}


def check_structure(tree: object, path: str) -> None:
    """Raise a one-line SceneError at the first property of ``tree`` (parsed JSON) of the wrong shape."""
    if not isinstance(tree, dict):
        raise SceneError(f"the top level must be a JSON object, got {_kind(tree)}", path=path, field="json")
    _check(tree, SCHEMA, "", path)


def _check(value, shape, where: str, path: str) -> None:
    if isinstance(shape, dict):
        if not isinstance(value, dict):
            raise SceneError(f"must be {OBJ}, got {_kind(value)}", path=path, field=where or "json")
        for key, sub in shape.items():
            if key in value:
                _check(value[key], sub, f"{where}.{key}" if where else key, path)
    elif isinstance(shape, tuple):
        kind, item = shape
        if kind == "list":
            if not isinstance(value, list):
                raise SceneError(f"must be an array, got {_kind(value)}", path=path, field=where)
            for i, v in enumerate(value):
                _check(v, item, f"{where}[{i}]", path)
        else:
            if not isinstance(value, dict):
                raise SceneError(f"must be {OBJ}, got {_kind(value)}", path=path, field=where)
            for k, v in value.items():
                _check(v, item, f"{where}.{k}", path)
    elif not _matches(value, shape):
        raise SceneError(f"must be {shape}, got {_kind(value)}", path=path, field=where)


def _matches(value, shape: str) -> bool:
    is_int = isinstance(value, int) and not isinstance(value, bool)
    if shape == INDEX:
        return is_int and value >= 0
    if shape == INT:
        return is_int
    if shape == NUM:
        return (is_int or isinstance(value, float)) and math.isfinite(value)
    if shape == STR:
        return isinstance(value, str)
    if shape == BOOL:
        return isinstance(value, bool)
    return isinstance(value, dict)  # OBJ


def _kind(value) -> str:
    """A short, bounded description of a JSON value for an error message."""
    if isinstance(value, dict):
        return "an object"
    if isinstance(value, list):
        return f"an array of {len(value)}"
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."
