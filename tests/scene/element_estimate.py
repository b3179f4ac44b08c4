"""Count the elements a glTF scene will get, by the element mesh's rule, to size the built-in scenes.

Rule (the loader's ElementMesh): each triangle, in world space at t = 0, is split uniformly into
n*n sub-triangles with n = ceil(longest edge / element_size), n >= 1; zero-area triangles are
dropped; a mesh used by two nodes counts twice. This module reads glTF independently of the
loader so tests can cross-check the two. Animation at t = 0 is the first key when keys start at
or after 0 (always so in our scenes); between keys it interpolates linearly, ignoring slerp and
cubic tangents, which is enough for an estimate.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pygltflib

from pipeline.scene.builtin.gltf_builder import GltfBuilder
from pipeline.scene.builtin.shapes import quaternion_matrix
from pipeline.scene.gltf import COMPONENT_DTYPES, TYPE_WIDTH


class GltfData:
    """A parsed glTF document with its buffers' bytes, enough to read accessors."""

    def __init__(self, source: GltfBuilder | bytes | str | Path):
        if isinstance(source, GltfBuilder):
            source = source.to_glb_bytes()
        if isinstance(source, (bytes, bytearray)):
            self.gltf = pygltflib.GLTF2.load_from_bytes(bytes(source))
            base = Path(".")
        else:
            self.gltf = pygltflib.GLTF2().load(str(source))
            base = Path(source).parent
        self.buffers = []
        for buffer in self.gltf.buffers:
            if buffer.uri is None:
                self.buffers.append(self.gltf.binary_blob())
            elif buffer.uri.startswith("data:"):
                self.buffers.append(pygltflib.GLTF2.decode_data_uri(buffer.uri))
            else:
                self.buffers.append((base / buffer.uri).read_bytes())

    def accessor(self, index: int) -> np.ndarray:
        """The accessor's elements as a (count, width) array (byteStride honoured, no sparse)."""
        acc = self.gltf.accessors[index]
        dtype = np.dtype(COMPONENT_DTYPES[acc.componentType])
        width = TYPE_WIDTH[acc.type]
        view = self.gltf.bufferViews[acc.bufferView]
        data = self.buffers[view.buffer]
        start = (view.byteOffset or 0) + (acc.byteOffset or 0)
        stride = view.byteStride or dtype.itemsize * width
        rows = np.ndarray((acc.count, width), dtype=dtype, buffer=data, offset=start,
                          strides=(stride, dtype.itemsize))
        return np.array(rows)


def _value_at(times: np.ndarray, values: np.ndarray, interpolation: str, t: float) -> np.ndarray:
    """A channel's value at ``t``: clamped to the key range, linear in between (an estimate)."""
    if interpolation == "CUBICSPLINE":
        values = values.reshape(len(times), 3, -1)[:, 1, :]
    if t <= times[0]:
        return values[0]
    if t >= times[-1]:
        return values[-1]
    k = int(np.searchsorted(times, t, side="right")) - 1
    if interpolation == "STEP":
        return values[k]
    w = (t - times[k]) / (times[k + 1] - times[k])
    return (1 - w) * values[k] + w * values[k + 1]


def _local_matrix(node: pygltflib.Node, animated: dict[str, np.ndarray]) -> np.ndarray:
    if node.matrix is not None and not animated:
        return np.asarray(node.matrix, dtype=np.float64).reshape(4, 4).T
    translation = animated.get("translation", node.translation or [0.0, 0.0, 0.0])
    rotation = animated.get("rotation", node.rotation or [0.0, 0.0, 0.0, 1.0])
    scale = animated.get("scale", node.scale or [1.0, 1.0, 1.0])
    m = np.eye(4)
    m[:3, :3] = quaternion_matrix(rotation) * np.asarray(scale, dtype=np.float64)
    m[:3, 3] = translation
    return m


def world_triangles(data: GltfData, t: float = 0.0) -> list[np.ndarray]:
    """World-space (m, 3, 3) triangle arrays, one per primitive instance, at time ``t``."""
    gltf = data.gltf
    animated: dict[int, dict[str, np.ndarray]] = {}
    for animation in gltf.animations:
        for channel in animation.channels:
            sampler = animation.samplers[channel.sampler]
            times = data.accessor(sampler.input).reshape(-1).astype(np.float64)
            values = data.accessor(sampler.output).astype(np.float64)
            value = _value_at(times, values, sampler.interpolation or "LINEAR", t)
            animated.setdefault(channel.target.node, {})[channel.target.path] = value
    out: list[np.ndarray] = []
    scene = gltf.scenes[gltf.scene or 0]
    stack = [(root, np.eye(4)) for root in scene.nodes]
    while stack:
        index, parent = stack.pop()
        node = gltf.nodes[index]
        world = parent @ _local_matrix(node, animated.get(index, {}))
        stack.extend((child, world) for child in node.children or [])
        if node.mesh is None:
            continue
        for primitive in gltf.meshes[node.mesh].primitives:
            positions = data.accessor(primitive.attributes.POSITION).astype(np.float64)
            positions = positions @ world[:3, :3].T + world[:3, 3]
            if primitive.indices is None:
                indices = np.arange(len(positions) - len(positions) % 3)
            else:
                indices = data.accessor(primitive.indices).reshape(-1).astype(np.int64)
            out.append(positions[indices.reshape(-1, 3)])
    return out


def elements_per_triangle(triangles: np.ndarray, element_size: float) -> np.ndarray:
    """n*n for each (m, 3, 3) triangle, 0 for zero-area ones."""
    edges = np.linalg.norm(triangles - np.roll(triangles, 1, axis=1), axis=2)
    longest = edges.max(axis=1)
    n = np.maximum(1, np.ceil(longest / element_size)).astype(np.int64)
    area2 = np.linalg.norm(np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1)
    return np.where(area2 > 0, n * n, 0)


def estimate_elements(source: GltfBuilder | bytes | str | Path, element_size: float | None = None) -> int:
    """Elements of the scene at t = 0; ``element_size`` defaults to the scene's own extras value."""
    data = GltfData(source)
    if element_size is None:
        element_size = scene_settings(data)["element_size"]
    if not (element_size > 0 and math.isfinite(element_size)):
        raise ValueError(f"element_size must be a positive number, not {element_size!r}")
    return int(sum(elements_per_triangle(tris, element_size).sum() for tris in world_triangles(data)))


def scene_settings(data: GltfData) -> dict:
    """The ``photonloom`` settings in the default scene's extras (empty when there are none)."""
    extras = data.gltf.scenes[data.gltf.scene or 0].extras or {}
    return dict(extras.get("photonloom", {}))
