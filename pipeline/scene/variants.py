"""Material variants (``KHR_materials_variants``): one file, several looks (a shoe in three colours).

The file names its variants at the top level (``extensions.KHR_materials_variants.variants``,
each ``{"name": ...}``) and maps, per primitive, a material to the variants that use it
(``mappings``: ``{"material": m, "variants": [v, ...]}``). Rendering a variant
(``loom render --variant NAME``) gives each mapped primitive its variant's material before the
scene is built; without ``--variant`` every primitive keeps its own ``material``, as the extension
asks. A variant is another scene: its name joins the file's digest, so its photons, segment
decisions and frames are never taken for another variant's. Spec: the extension's README.
"""
from __future__ import annotations

import hashlib

from .gltf import GltfDocument

EXTENSION = "KHR_materials_variants"


def variant_names(doc: GltfDocument) -> list[str]:
    """The names of the file's variants, in their order ([] without the extension)."""
    root = (doc.gltf.extensions or {}).get(EXTENSION)
    if root is None:
        return []
    where = f"extensions.{EXTENSION}.variants"
    variants = root.get("variants") if isinstance(root, dict) else None
    if not isinstance(variants, list):
        raise doc.error("must be a list of variants", where)
    names = []
    for i, v in enumerate(variants):
        if not isinstance(v, dict) or not isinstance(v.get("name"), str):
            raise doc.error("must be an object with a name", f"{where}[{i}]")
        names.append(v["name"])
    return names


def apply_variant(doc: GltfDocument, name: str) -> None:
    """Give every primitive mapped for the variant ``name`` that variant's material, and make the
    document's digest the variant's; a one-line error for an unknown name or a bad mapping."""
    names = variant_names(doc)
    if name not in names:
        choices = ", ".join(repr(n) for n in names) if names else "none (the file has no KHR_materials_variants)"
        raise doc.error(f"no variant {name!r}: the file's variants are {choices}", "--variant")
    chosen = names.index(name)
    raw_meshes = doc.tree.get("meshes", [])
    for m, mesh in enumerate(doc.gltf.meshes):
        for p, prim in enumerate(mesh.primitives):
            ext = raw_meshes[m]["primitives"][p].get("extensions", {}).get(EXTENSION)
            if ext is None:
                continue
            where = f"meshes[{m}].primitives[{p}].extensions.{EXTENSION}.mappings"
            mappings = ext.get("mappings") if isinstance(ext, dict) else None
            if not isinstance(mappings, list):
                raise doc.error("must be a list of mappings", where)
            for i, mapping in enumerate(mappings):
                material, variants = (mapping.get("material"), mapping.get("variants")) if isinstance(
                    mapping, dict) else (None, None)
                if not isinstance(material, int) or not 0 <= material < len(doc.gltf.materials):
                    raise doc.error(f"refers to a missing material {material!r}", f"{where}[{i}].material")
                if not isinstance(variants, list) or not all(isinstance(v, int) and 0 <= v < len(names)
                                                             for v in variants):
                    raise doc.error(f"must list variants 0 to {len(names) - 1}, got {variants!r}",
                                    f"{where}[{i}].variants")
                if chosen in variants:
                    prim.material = material
    doc.digest = hashlib.sha256(f"{doc.digest}\0{EXTENSION}\0{name}".encode()).hexdigest()
