"""What a glTF file holds that photonloom does not render, each with the reason (``loom info``).

Skins and morph targets are rendered (pipeline/scene/animation.py; ``loom info`` lists what deforms
on its ``deforms`` line). Extensions outside the ones
implemented are ignored with the core glTF data they extend, or refused by the loader when the
file lists them in ``extensionsRequired``; ``KHR_animation_pointer`` pointers that are not animated
are the loader's warnings (pipeline/scene/pointers.py). Only the default scene is rendered, and only
perspective and orthographic cameras can be chosen.
"""
from __future__ import annotations

from .gltf import SUPPORTED_REQUIRED_EXTENSIONS
from .scene import Scene

# Why an extension that is only "used" (not required) is safe to ignore, by name prefix; the
# file's core data is what gets rendered.
_REASONS = (
    ("KHR_materials_", "the core metallic-roughness factors are used"),
    ("KHR_texture_", "the core texture reference is used"),
    ("EXT_texture_", "the core texture reference is used"),
    ("KHR_xmp", "metadata does not change the picture"),
)


def ignored(scene: Scene) -> list[str]:
    """One line per kind of thing the file holds and the render leaves out, with the reason."""
    g = scene.document.gltf
    lines = []
    for name in sorted(_extensions(g) - SUPPORTED_REQUIRED_EXTENSIONS):
        reason = next((why for prefix, why in _REASONS if name.startswith(prefix)), "the core glTF data is used")
        lines.append(f"extension {name}: not implemented, {reason}")
    unknown = sum(1 for c in g.cameras if c.type not in ("perspective", "orthographic"))
    if unknown:
        lines.append(f"{unknown} camera(s) neither perspective nor orthographic: they cannot render")
    if scene.animations_left_out:
        lines.append(f"{len(scene.animations_left_out)} animation(s) {', '.join(scene.animations_left_out)}: "
                     f"alternative clips of nodes {scene.animations_played[0]} animates; one clip plays at a time "
                     "(--animation NAME)")
    if len(g.scenes) > 1:
        lines.append(f"{len(g.scenes) - 1} scene(s) besides the default: only the default scene is rendered")
    return lines


def _extensions(g) -> set[str]:
    """Extension names the file declares or uses on any object."""
    names = set(g.extensionsUsed or ()) | set(g.extensionsRequired or ())
    for objects in (g.materials, g.nodes, g.meshes, g.textures, g.images, g.cameras, g.scenes, g.animations):
        for obj in objects or ():
            names |= set(getattr(obj, "extensions", None) or {})
    for mesh in g.meshes or ():
        for prim in mesh.primitives:
            names |= set(prim.extensions or {})
    names |= set(g.extensions or {})
    return names
