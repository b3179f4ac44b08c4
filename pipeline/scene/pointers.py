"""What a ``KHR_animation_pointer`` channel animates: its JSON pointer read as a target of the
scene (the extension's specification; the glTF 2.0 Asset Object Model names the pointers).

A pointer becomes a key ``(kind, index, property)`` of the loader's channels
(pipeline/scene/loader.py): "node" for a node's TRS or morph weights (the core targets written as
pointers), "visibility" for KHR_node_visibility's ``visible`` (pipeline/scene/visibility.py),
"light" for a punctual light's colour, intensity, range and spot cone angles, "material" for the
properties of materials.ANIMATED_PROPERTIES (factors, emission, texture transforms, alpha
cut-off), "camera" for a perspective camera's ``yfov`` or an orthographic one's ``ymag``.
Properties a ray-traced picture here does not depend on (a camera's clip planes, aspect ratio and
xmag: the output resolution sets the aspect) are accepted and change nothing. Any other pointer
keeps the file's value, and a file that requires the extension is refused for it.
"""
from __future__ import annotations

import re
from typing import TYPE_CHECKING

from .gltf import GltfDocument
from .materials import ANIMATED_PROPERTIES, MATERIAL_WIDTHS, NON_NEGATIVE, TEXTURE_SLOTS, texture_info
from .visibility import EXTENSION as VISIBILITY

if TYPE_CHECKING:
    from pygltflib import AnimationChannelTarget

EXTENSION = "KHR_animation_pointer"
# What the pointers animate here, for messages
ANIMATED_POINTERS = ("node translation, rotation, scale, morph weights and visibility, light colour, intensity, "
                     "range and spot cones, material factors, emission and texture transforms, and a camera's "
                     "field of view or orthographic height")
# Values a key of each animated property holds (a sampler's output width); morph weights: one per target
WIDTHS = {"translation": 3, "rotation": 4, "scale": 3, "visible": 1, "intensity": 1, "color": 3, "range": 1,
          "innerConeAngle": 1, "outerConeAngle": 1, "yfov": 1, "ymag": 1, **MATERIAL_WIDTHS}
# Light and material properties whose keys must not be negative
NON_NEGATIVE_PROPERTIES = NON_NEGATIVE | {"intensity", "color", "range", "innerConeAngle", "outerConeAngle"}
# A boolean's keys: unsigned bytes, 0 false (the extension's "Output Accessor Component Types")
BOOLEAN_ACCESSOR = {"types": ("SCALAR",), "components": (5121,)}

_NODE = re.compile(r"/nodes/(\d+)/(translation|rotation|scale|weights)")
_VISIBILITY = re.compile(r"/nodes/(\d+)/extensions/" + VISIBILITY + "/visible")
_LIGHT = re.compile(r"/extensions/KHR_lights_punctual/lights/(\d+)/(intensity|color|range|spot/innerConeAngle|"
                    r"spot/outerConeAngle)")
_CAMERA = re.compile(r"/cameras/(\d+)/(perspective/yfov|orthographic/ymag)")
_MATERIAL = re.compile(r"/materials/(\d+)/(" + "|".join(map(re.escape, ANIMATED_PROPERTIES)) + ")")
_NO_EFFECT = re.compile(r"/cameras/\d+/(perspective/(znear|zfar|aspectRatio)|orthographic/(xmag|znear|zfar))")


def pointer_target(doc: GltfDocument, target: AnimationChannelTarget, f: str, unsupported: set[str]) -> tuple | None:
    """The key ``(kind, index, property)`` of a KHR_animation_pointer channel's ``target`` (at
    field ``f`` of ``doc``); None for a pointer that changes nothing here, or for one not animated
    here, whose pattern is added to ``unsupported``. A pointer to something the file lacks is a
    one-line error."""
    pointer = ((target.extensions or {}).get(EXTENSION) or {}).get("pointer")
    where = f + ".target.extensions.KHR_animation_pointer.pointer"
    if not isinstance(pointer, str) or not pointer.startswith("/"):
        raise doc.error(f"pointer {pointer!r} must be a JSON pointer string", where)
    g = doc.gltf
    if node := _NODE.fullmatch(pointer):
        return "node", int(node.group(1)), node.group(2)
    if shown := _VISIBILITY.fullmatch(pointer):
        return "visibility", int(shown.group(1)), "visible"
    if light := _LIGHT.fullmatch(pointer):
        lights = (g.extensions or {}).get("KHR_lights_punctual", {}).get("lights", [])
        i, prop = int(light.group(1)), light.group(2).removeprefix("spot/")
        if not i < len(lights):
            raise doc.error(f"{pointer} points to missing light {i}", where)
        if prop == "range" and lights[i].get("range") is None:  # no default value (the extension, "Operation")
            raise doc.error(f"{pointer}: light {i} defines no range to animate", where)
        if prop.endswith("ConeAngle") and lights[i].get("type") != "spot":
            raise doc.error(f"{pointer}: light {i} is not a spot light", where)
        return "light", i, prop
    if camera := _CAMERA.fullmatch(pointer):
        if not int(camera.group(1)) < len(g.cameras):
            raise doc.error(f"{pointer} points to missing camera {camera.group(1)}", where)
        return "camera", int(camera.group(1)), camera.group(2).split("/")[1]
    if material := _MATERIAL.fullmatch(pointer):
        i, prop = int(material.group(1)), ANIMATED_PROPERTIES[material.group(2)][0]
        if not i < len(g.materials):
            raise doc.error(f"{pointer} points to missing material {i}", where)
        slot = prop.split(".")[0]
        if slot in TEXTURE_SLOTS and texture_info(g.materials[i], slot) is None:
            raise doc.error(f"{pointer}: material {i} has no {slot} to transform", where)
        return "material", i, prop
    if not _NO_EFFECT.fullmatch(pointer):
        unsupported.add(re.sub(r"/\d+(?=/|$)", "/{i}", pointer))
    return None

