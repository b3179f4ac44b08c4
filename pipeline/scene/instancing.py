"""``EXT_mesh_gpu_instancing``: one node drawing its mesh many times, each copy placed by its own
translation, rotation and scale (a forest of one tree, a field of one stone).

The instance transforms come first: a vertex goes to ``NodeWorld x (T R S)_k x p`` (the
extension's specification, "Transformation Order"). Each copy becomes a mesh instance of its own
whose vertices (and normals) are already placed in the node's space, so it moves with the node as
any mesh does and gets its own elements; a copy whose transform mirrors it has its triangles'
corners reversed, which keeps their front faces where glTF puts them (§3.7.2.1, the winding of a
negative determinant). The mesh itself is not drawn besides its copies. A skinned or morphed mesh
is not instanced here (its pose is per vertex, in world space), and is refused.
"""
from __future__ import annotations

import numpy as np

from .animation import quaternion_matrix, transform_normals
from .gltf import GltfDocument

EXTENSION = "EXT_mesh_gpu_instancing"
# The attributes that place copies, their accessor types and component types (the specification's table)
_ATTRIBUTES = {"TRANSLATION": ("VEC3", (5126,)), "ROTATION": ("VEC4", (5126, 5120, 5122)),
               "SCALE": ("VEC3", (5126,))}


def instance_transforms(doc: GltfDocument, node: int) -> np.ndarray | None:
    """(N, 4, 4) the transforms T R S of node ``node``'s copies, or None where the node has no
    ``EXT_mesh_gpu_instancing``; attributes other than those that place copies (``_ID``) are ignored."""
    ext = ((doc.gltf.nodes[node].extensions or {}).get(EXTENSION))
    if ext is None:
        return None
    where = f"nodes[{node}].extensions.{EXTENSION}.attributes"
    attributes = ext.get("attributes") if isinstance(ext, dict) else None
    if not isinstance(attributes, dict):
        raise doc.error("must be an object of accessors", where)
    values = {}
    for name, (kind, components) in _ATTRIBUTES.items():
        if name in attributes:
            values[name] = np.asarray(doc.accessor(attributes[name], f"{where}.{name}", types=(kind,),
                                                   components=components), np.float64)
    if not values:
        raise doc.error("places no copy: none of TRANSLATION, ROTATION, SCALE", where)
    counts = {len(v) for v in values.values()}
    if len(counts) != 1:
        raise doc.error(f"TRANSLATION, ROTATION and SCALE must have one count, got {sorted(counts)}", where)
    n = counts.pop()
    if not all(np.isfinite(v).all() for v in values.values()):
        raise doc.error("holds NaN or Inf", where)
    rotation = values.get("ROTATION", np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)))
    norms = np.linalg.norm(rotation, axis=1)
    if np.any(norms < 1e-6):
        raise doc.error(f"ROTATION of copy {int(np.argmax(norms < 1e-6))} is a zero quaternion", where + ".ROTATION")
    out = np.zeros((n, 4, 4))
    out[:, :3, :3] = quaternion_matrix(rotation) * values.get("SCALE", np.ones((n, 3)))[:, None, :]  # T R S
    out[:, :3, 3] = values.get("TRANSLATION", np.zeros((n, 3)))
    out[:, 3, 3] = 1.0
    return out


def place_copy(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray | None, transform: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """One copy's vertices, faces and normals in its node's space: ``transform`` (4, 4) applied,
    normals by its cofactor matrix, corners reversed where it mirrors (see the module docstring)."""
    linear = transform[:3, :3]
    placed = vertices @ linear.T + transform[:3, 3]
    turned = None if normals is None else transform_normals(normals, linear)
    return placed, (faces[:, ::-1].copy() if np.linalg.det(linear) < 0 else faces), turned
