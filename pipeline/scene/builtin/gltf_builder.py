"""A small glTF 2.0 writer on pygltflib, used by the built-in scenes and by tests that need glTF files.

Everything goes into one binary buffer: every accessor starts on a 4-byte boundary, vertex and index
data get their bufferView targets, animation inputs carry the min/max the specification requires,
extensions (``KHR_lights_punctual``, ``KHR_materials_emissive_strength``) are listed in
``extensionsUsed`` when used. Output is ``.glb`` (one BIN chunk) or ``.gltf`` (JSON with the buffer as
a base64 data URI, or as an external ``.bin`` next to it).

Indices returned by the ``add_*`` methods are glTF indices (material, mesh, node, light, camera), to
be passed to later calls. Nodes that no other node lists as a child become the scene's roots.
"""
from __future__ import annotations

import base64
import json
import math
import os
import struct
import tempfile
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np
import pygltflib
from pygltflib import (
    GLTF2,
    Accessor,
    Animation,
    AnimationChannel,
    AnimationChannelTarget,
    AnimationSampler,
    Asset,
    Attributes,
    Buffer,
    BufferView,
    Camera,
    Material,
    Mesh,
    Node,
    PbrMetallicRoughness,
    Perspective,
    Primitive,
    Scene,
    Skin,
)

from pipeline.scene.gltf import COMPONENT_DTYPES, TYPE_WIDTH

LIGHTS_EXTENSION = "KHR_lights_punctual"
EMISSIVE_STRENGTH_EXTENSION = "KHR_materials_emissive_strength"
POINTER_EXTENSION = "KHR_animation_pointer"
TEXTURE_TRANSFORM_EXTENSION = "KHR_texture_transform"
VISIBILITY_EXTENSION = "KHR_node_visibility"

TRIANGLES = 4
ARRAY_BUFFER = 34962
ELEMENT_ARRAY_BUFFER = 34963

_COMPONENT_TYPES = {np.dtype(dtype): code for code, dtype in COMPONENT_DTYPES.items()}
# Widths written: SCALAR, VEC2..4 and MAT4 (MAT2 and MAT3 are never written; MAT2 shares VEC4's width)
_ACCESSOR_TYPES = {TYPE_WIDTH[t]: t for t in ("SCALAR", "VEC2", "VEC3", "VEC4", "MAT4")}
_PATH_WIDTH = {"translation": 3, "rotation": 4, "scale": 3}
_INTERPOLATIONS = ("LINEAR", "STEP", "CUBICSPLINE")


def _floats(values: Iterable[float]) -> list[float]:
    """Plain Python floats for the JSON (numpy scalars do not serialise)."""
    return [float(v) for v in values]


def _key_times(name: str, times: Sequence[float], interpolation: str) -> np.ndarray:
    """An animation's key times as float32, checked with its interpolation."""
    if interpolation not in _INTERPOLATIONS:
        raise ValueError(f"animation {name!r}: interpolation must be one of {_INTERPOLATIONS}")
    times = np.asarray(times, dtype=np.float32).reshape(-1)
    if times.size == 0 or not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
        raise ValueError(f"animation {name!r}: key times must be finite and strictly increasing")
    return times


def normalized_quaternion(q: Sequence[float]) -> list[float]:
    """An xyzw quaternion scaled to unit length, as glTF requires for rotations."""
    q = np.asarray(q, dtype=np.float64)
    norm = float(np.linalg.norm(q))
    if not math.isfinite(norm) or norm == 0.0:
        raise ValueError(f"rotation quaternion {q.tolist()} has no direction")
    return _floats(q / norm)


def encode_png(pixels: np.ndarray) -> bytes:
    """8-bit RGB ``pixels`` (H, W, 3) as PNG bytes, written by OpenImageIO."""
    import OpenImageIO as oiio  # heavy: only where images are read or written

    pixels = np.ascontiguousarray(pixels, dtype=np.uint8)
    fd, name = tempfile.mkstemp(suffix=".png")
    os.close(fd)
    try:
        out = oiio.ImageOutput.create(name)
        out.open(name, oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], "uint8"))
        out.write_image(pixels)
        out.close()
        return Path(name).read_bytes()
    finally:
        os.unlink(name)


class GltfBuilder:
    """Accumulates one glTF 2.0 scene (one buffer, one default scene) and writes it out."""

    def __init__(self, scene_name: str = "scene", generator: str = "photonloom GltfBuilder"):
        self.gltf = GLTF2(asset=Asset(version="2.0", generator=generator))
        self.gltf.scenes = [Scene(name=scene_name)]
        self.gltf.scene = 0
        self._blob = bytearray()
        self._lights: list[dict] = []
        self._animations_by_name: dict[str, int] = {}
        self._node_weights: dict[int, list[float]] = {}  # node -> its default morph weights

    # -- raw data -------------------------------------------------------------------------------

    def add_accessor(self, data: np.ndarray, *, target: int | None = None, with_bounds: bool = False,
                     name: str | None = None) -> int:
        """Append ``data`` (count x width, or a flat array of scalars) as a bufferView + accessor.

        The dtype picks the componentType (float32, uint32, uint16, ...); the width picks the type
        (SCALAR, VEC2..4, MAT4). ``with_bounds`` writes per-component min/max.
        """
        data = np.ascontiguousarray(data)
        if data.dtype not in _COMPONENT_TYPES:
            raise ValueError(f"accessor dtype {data.dtype} is not a glTF component type")
        if data.ndim == 1:
            data = data.reshape(-1, 1)
        width = data.shape[1]
        if width not in _ACCESSOR_TYPES:
            raise ValueError(f"accessor rows of {width} components have no glTF type")
        if data.dtype.kind == "f" and not np.all(np.isfinite(data)):
            raise ValueError(f"accessor {name or ''} holds NaN or Inf")
        self._pad_blob()
        offset = len(self._blob)
        raw = data.tobytes()
        self._blob += raw
        view = BufferView(buffer=0, byteOffset=offset, byteLength=len(raw), target=target)
        self.gltf.bufferViews.append(view)
        accessor = Accessor(bufferView=len(self.gltf.bufferViews) - 1, byteOffset=0,
                            componentType=_COMPONENT_TYPES[data.dtype], count=int(data.shape[0]),
                            type=_ACCESSOR_TYPES[width], name=name)
        if with_bounds and data.shape[0]:
            cast = float if data.dtype.kind == "f" else int
            accessor.min = [cast(v) for v in data.min(axis=0)]
            accessor.max = [cast(v) for v in data.max(axis=0)]
        self.gltf.accessors.append(accessor)
        return len(self.gltf.accessors) - 1

    def _pad_blob(self) -> None:
        self._blob += b"\0" * (-len(self._blob) % 4)

    # -- materials and meshes -------------------------------------------------------------------

    def add_material(self, name: str, base_color: Sequence[float], metallic: float = 0.0,
                     roughness: float = 1.0, emissive: Sequence[float] = (0.0, 0.0, 0.0),
                     emissive_strength: float = 1.0, double_sided: bool | None = None,
                     base_color_texture: int | None = None, texcoord: int = 0,
                     texture_transform: dict | None = None, emissive_texture: int | None = None,
                     normal_texture: int | None = None, normal_scale: float = 1.0, alpha_mode: str | None = None,
                     alpha_cutoff: float | None = None, metallic_roughness_texture: int | None = None) -> int:
        """A metallic-roughness material; ``base_color`` is RGB or RGBA (the Lambertian albedo).

        ``base_color_texture`` is a texture index from :meth:`add_texture`, looked up with
        ``TEXCOORD_<texcoord>`` and an optional ``KHR_texture_transform`` (offset, rotation, scale);
        ``emissive_texture`` multiplies the emission, ``normal_texture`` (scaled by ``normal_scale``)
        bends the shading normal, ``metallic_roughness_texture`` scales ``metallic`` by its blue channel
        and ``roughness`` by its green, all looked up with the same set.

        Emitted radiance is ``emissive * emissive_strength``; a strength other than 1 is written as
        ``KHR_materials_emissive_strength``. ``double_sided`` defaults to True for surfaces that do
        not emit (our surfaces reflect on both faces) and False for emitters (front face only).
        """
        rgba = _floats(base_color)
        if len(rgba) == 3:
            rgba.append(1.0)
        if len(rgba) != 4:
            raise ValueError(f"material {name!r}: base_color needs 3 or 4 components")
        emissive = _floats(emissive)
        if len(emissive) != 3:
            raise ValueError(f"material {name!r}: emissive needs 3 components")
        emits = any(e > 0 for e in emissive) and emissive_strength > 0
        if double_sided is None:
            double_sided = not emits
        material = Material(
            name=name,
            pbrMetallicRoughness=PbrMetallicRoughness(baseColorFactor=rgba, metallicFactor=float(metallic),
                                                      roughnessFactor=float(roughness)),
            emissiveFactor=emissive,
            doubleSided=bool(double_sided),
        )
        if base_color_texture is not None:
            info = pygltflib.TextureInfo(index=int(base_color_texture), texCoord=int(texcoord))
            if texture_transform is not None:
                info.extensions = {TEXTURE_TRANSFORM_EXTENSION: dict(texture_transform)}
                self._use_extension(TEXTURE_TRANSFORM_EXTENSION)
            material.pbrMetallicRoughness.baseColorTexture = info
        if metallic_roughness_texture is not None:
            material.pbrMetallicRoughness.metallicRoughnessTexture = pygltflib.TextureInfo(
                index=int(metallic_roughness_texture), texCoord=int(texcoord))
        if emissive_texture is not None:
            material.emissiveTexture = pygltflib.TextureInfo(index=int(emissive_texture), texCoord=int(texcoord))
        if alpha_mode is not None:  # OPAQUE, MASK (holes where alpha < alpha_cutoff) or BLEND
            material.alphaMode = alpha_mode
            material.alphaCutoff = None if alpha_cutoff is None else float(alpha_cutoff)
        if normal_texture is not None:
            material.normalTexture = pygltflib.NormalMaterialTexture(index=int(normal_texture), texCoord=int(texcoord),
                                                                     scale=float(normal_scale))
        if emissive_strength != 1.0:
            material.extensions[EMISSIVE_STRENGTH_EXTENSION] = {"emissiveStrength": float(emissive_strength)}
            self._use_extension(EMISSIVE_STRENGTH_EXTENSION)
        self.gltf.materials.append(material)
        return len(self.gltf.materials) - 1

    def add_mesh(self, name: str, positions: np.ndarray, indices: np.ndarray | None = None,
                 material: int | None = None, normals: np.ndarray | None = None, mode: int = TRIANGLES,
                 index_dtype: type = np.uint32, texcoords: dict | None = None,
                 colors: np.ndarray | None = None) -> int:
        """A mesh with one primitive; returns the mesh index. See :meth:`add_primitive`."""
        self.gltf.meshes.append(Mesh(name=name))
        mesh = len(self.gltf.meshes) - 1
        self.add_primitive(mesh, positions, indices, material, normals=normals, mode=mode,
                           index_dtype=index_dtype, texcoords=texcoords, colors=colors)
        return mesh

    def add_primitive(self, mesh: int, positions: np.ndarray, indices: np.ndarray | None = None,
                      material: int | None = None, normals: np.ndarray | None = None, mode: int = TRIANGLES,
                      index_dtype: type = np.uint32, texcoords: dict | None = None,
                      colors: np.ndarray | None = None) -> int:
        """Add a primitive to ``mesh``: float32 POSITION (with min/max), optional NORMAL, indices.

        ``texcoords`` maps a set number to (V, 2) texture coordinates (``TEXCOORD_<set>``),
        ``colors`` is (V, 3) or (V, 4) linear ``COLOR_0``.

        Without ``indices`` the primitive is non-indexed (every 3 positions are a triangle).
        ``mode`` other than TRIANGLES is allowed so tests can write primitives a loader must refuse.
        """
        positions = np.asarray(positions, dtype=np.float32).reshape(-1, 3)
        attributes = Attributes(POSITION=self.add_accessor(positions, target=ARRAY_BUFFER, with_bounds=True))
        if normals is not None:
            normals = np.asarray(normals, dtype=np.float32).reshape(-1, 3)
            if normals.shape != positions.shape:
                raise ValueError("normals must have one row per position")
            attributes.NORMAL = self.add_accessor(normals, target=ARRAY_BUFFER)
        for n_set, uv in (texcoords or {}).items():
            uv = np.asarray(uv, dtype=np.float32).reshape(-1, 2)
            if len(uv) != len(positions):
                raise ValueError("texture coordinates must have one row per position")
            setattr(attributes, f"TEXCOORD_{int(n_set)}", self.add_accessor(uv, target=ARRAY_BUFFER))
        if colors is not None:
            colors = np.asarray(colors, dtype=np.float32)
            if colors.ndim != 2 or len(colors) != len(positions) or colors.shape[1] not in (3, 4):
                raise ValueError("colors must be (V, 3) or (V, 4), one row per position")
            attributes.COLOR_0 = self.add_accessor(colors, target=ARRAY_BUFFER)
        primitive = Primitive(attributes=attributes, material=material, mode=int(mode))
        if indices is not None:
            indices = np.asarray(indices).reshape(-1)
            if indices.size and (indices.min() < 0 or indices.max() >= len(positions)):
                raise ValueError("indices refer to positions that do not exist")
            primitive.indices = self.add_accessor(indices.astype(index_dtype), target=ELEMENT_ARRAY_BUFFER)
        self.gltf.meshes[mesh].primitives.append(primitive)
        return len(self.gltf.meshes[mesh].primitives) - 1

    def add_morph_targets(self, mesh: int, primitive: int, positions: Sequence[np.ndarray],
                          normals: Sequence[np.ndarray] | None = None,
                          weights: Sequence[float] | None = None) -> None:
        """Morph targets of a primitive (glTF 2.0 §3.7.2.2): per target, (V, 3) POSITION
        displacements and optionally NORMAL displacements; ``weights`` become ``mesh.weights``."""
        prim = self.gltf.meshes[mesh].primitives[primitive]
        prim.targets = []
        for k, dp in enumerate(positions):
            target = {"POSITION": self.add_accessor(np.asarray(dp, np.float32).reshape(-1, 3), with_bounds=True)}
            if normals is not None:
                target["NORMAL"] = self.add_accessor(np.asarray(normals[k], np.float32).reshape(-1, 3))
            prim.targets.append(target)
        if weights is not None:
            self.gltf.meshes[mesh].weights = _floats(weights)

    def add_skin(self, joints: Sequence[int], inverse_bind: np.ndarray | None = None, name: str | None = None) -> int:
        """A skin over ``joints`` (node indices) with (J, 4, 4) row-major inverse bind matrices
        (written column-major as glTF wants); returns the skin index."""
        skin = Skin(joints=[int(j) for j in joints], name=name)
        if inverse_bind is not None:
            m = np.asarray(inverse_bind, np.float64).reshape(-1, 4, 4)
            skin.inverseBindMatrices = self.add_accessor(m.transpose(0, 2, 1).reshape(-1, 16).astype(np.float32))
        self.gltf.skins.append(skin)
        return len(self.gltf.skins) - 1

    def bind_skin(self, mesh: int, primitive: int, joints: np.ndarray, weights: np.ndarray) -> None:
        """JOINTS_n / WEIGHTS_n of a primitive from (V, 4n) joint indices and weights (glTF §3.7.3.1)."""
        joints = np.asarray(joints).reshape(len(joints), -1)
        weights = np.asarray(weights, np.float32).reshape(len(weights), -1)
        if joints.shape != weights.shape or joints.shape[1] % 4:
            raise ValueError("joints and weights must both be (V, 4n)")
        attributes = self.gltf.meshes[mesh].primitives[primitive].attributes
        for n in range(joints.shape[1] // 4):
            setattr(attributes, f"JOINTS_{n}", self.add_accessor(joints[:, 4 * n:4 * n + 4].astype(np.uint16)))
            setattr(attributes, f"WEIGHTS_{n}", self.add_accessor(weights[:, 4 * n:4 * n + 4]))

    # -- textures -------------------------------------------------------------------------------

    def add_texture(self, pixels: np.ndarray, *, uri: str | None = None, wrap_s: int = 10497,
                    wrap_t: int = 10497, mag_filter: int | None = None, min_filter: int | None = None) -> int:
        """A texture of the 8-bit sRGB image ``pixels`` (H, W, 3), PNG-encoded with OpenImageIO and
        embedded in the buffer (a bufferView), or with ``uri`` referenced as an external file the
        caller writes (:func:`encode_png`). Returns the texture index."""
        if uri is None:
            data = encode_png(pixels)
            self._pad_blob()
            offset = len(self._blob)
            self._blob += data
            self.gltf.bufferViews.append(BufferView(buffer=0, byteOffset=offset, byteLength=len(data)))
            image = pygltflib.Image(bufferView=len(self.gltf.bufferViews) - 1, mimeType="image/png")
        else:
            image = pygltflib.Image(uri=uri)
        self.gltf.images.append(image)
        self.gltf.samplers.append(pygltflib.Sampler(wrapS=int(wrap_s), wrapT=int(wrap_t), magFilter=mag_filter,
                                                    minFilter=min_filter))
        self.gltf.textures.append(pygltflib.Texture(sampler=len(self.gltf.samplers) - 1,
                                                    source=len(self.gltf.images) - 1))
        return len(self.gltf.textures) - 1

    # -- lights and cameras ---------------------------------------------------------------------

    def add_point_light(self, name: str, color: Sequence[float], intensity: float,
                        range: float | None = None) -> int:
        """A KHR_lights_punctual point light; ``intensity * color`` is radiant intensity (W/sr)."""
        return self._add_light(name, "point", color, intensity, range)

    def add_spot_light(self, name: str, color: Sequence[float], intensity: float,
                       inner_cone_angle: float = 0.0, outer_cone_angle: float = math.pi / 4,
                       range: float | None = None) -> int:
        """A spot light shining down its node's -Z; cone angles in radians, 0 <= inner < outer <= pi/2."""
        if not 0.0 <= inner_cone_angle < outer_cone_angle <= math.pi / 2:
            raise ValueError(f"spot light {name!r}: need 0 <= inner < outer <= pi/2")
        spot = {"innerConeAngle": float(inner_cone_angle), "outerConeAngle": float(outer_cone_angle)}
        return self._add_light(name, "spot", color, intensity, range, spot=spot)

    def add_directional_light(self, name: str, color: Sequence[float], intensity: float,
                              range: float | None = None) -> int:
        """A directional light shining down its node's -Z; ``intensity * color`` is irradiance.

        ``range`` is accepted for symmetry but the specification says directional lights have none,
        so it is not written.
        """
        del range
        return self._add_light(name, "directional", color, intensity, None)

    def _add_light(self, name: str, kind: str, color: Sequence[float], intensity: float,
                   range: float | None, spot: dict | None = None) -> int:
        light = {"name": name, "type": kind, "color": _floats(color), "intensity": float(intensity)}
        if len(light["color"]) != 3:
            raise ValueError(f"light {name!r}: color needs 3 components")
        if range is not None:
            if range <= 0:
                raise ValueError(f"light {name!r}: range must be positive")
            light["range"] = float(range)
        if spot is not None:
            light["spot"] = spot
        self._lights.append(light)
        self._use_extension(LIGHTS_EXTENSION)
        return len(self._lights) - 1

    def add_camera(self, name: str, yfov: float, znear: float, zfar: float | None = None,
                   aspect: float | None = None) -> int:
        """A perspective camera (looks down its node's -Z, +Y up); ``yfov`` in radians."""
        perspective = Perspective(yfov=float(yfov), znear=float(znear),
                                  zfar=None if zfar is None else float(zfar),
                                  aspectRatio=None if aspect is None else float(aspect))
        self.gltf.cameras.append(Camera(name=name, type="perspective", perspective=perspective))
        return len(self.gltf.cameras) - 1

    # -- nodes ----------------------------------------------------------------------------------

    def add_node(self, name: str, mesh: int | None = None, *, translation: Sequence[float] | None = None,
                 rotation: Sequence[float] | None = None, scale: Sequence[float] | None = None,
                 matrix: np.ndarray | Sequence[float] | None = None, children: Sequence[int] = (),
                 camera: int | None = None, light: int | None = None, skin: int | None = None,
                 weights: Sequence[float] | None = None, visible: bool | None = None) -> int:
        """A node with either TRS (rotation an xyzw quaternion, normalised here) or a 4x4 matrix;
        ``visible`` writes KHR_node_visibility's property.

        ``matrix`` is given in the usual row-major mathematical layout (translation in the last
        column) and written column-major as glTF wants. ``children`` must already exist.
        """
        if matrix is not None and any(v is not None for v in (translation, rotation, scale)):
            raise ValueError(f"node {name!r}: give either matrix or translation/rotation/scale")
        node = Node(name=name, mesh=mesh, camera=camera, children=[int(c) for c in children], skin=skin)
        if weights is not None:
            self._node_weights[len(self.gltf.nodes)] = _floats(weights)
        for child in node.children:
            if not 0 <= child < len(self.gltf.nodes):
                raise ValueError(f"node {name!r}: child {child} does not exist yet")
        if translation is not None:
            node.translation = _floats(translation)
        if rotation is not None:
            node.rotation = normalized_quaternion(rotation)
        if scale is not None:
            node.scale = _floats(scale)
        if matrix is not None:
            m = np.asarray(matrix, dtype=np.float64).reshape(4, 4)
            node.matrix = _floats(m.T.reshape(-1))
        if light is not None:
            if not 0 <= light < len(self._lights):
                raise ValueError(f"node {name!r}: light {light} does not exist")
            node.extensions[LIGHTS_EXTENSION] = {"light": int(light)}
        if visible is not None:
            node.extensions[VISIBILITY_EXTENSION] = {"visible": bool(visible)}
            self._use_extension(VISIBILITY_EXTENSION)
        self.gltf.nodes.append(node)
        return len(self.gltf.nodes) - 1

    def add_child(self, parent: int, child: int) -> None:
        """Make ``child`` a child of ``parent`` after both exist."""
        self.gltf.nodes[parent].children.append(int(child))

    # -- animation ------------------------------------------------------------------------------

    def add_animation(self, name: str, node: int, path: str, times: Sequence[float],
                      values: np.ndarray | Sequence, interpolation: str = "LINEAR") -> int:
        """Animate ``node``'s translation, rotation, scale or morph ``weights``; returns the animation index.

        Channels added under the same ``name`` share one glTF animation. ``values`` has one row per
        key (xyz, xyzw for rotation, one weight per morph target); for CUBICSPLINE, three rows per key in the order
        in-tangent, value, out-tangent (shape (keys, 3, width) or (3*keys, width)). Rotation values
        are normalised (tangents are not). Times must be finite and strictly increasing.
        """
        if path not in _PATH_WIDTH and path != "weights":
            raise ValueError(f"animation {name!r}: path must be one of {sorted(_PATH_WIDTH) + ['weights']}")
        times = _key_times(name, times, interpolation)
        rows_per_key = 3 if interpolation == "CUBICSPLINE" else 1
        width = _PATH_WIDTH[path] if path != "weights" else np.asarray(values).size // (times.size * rows_per_key)
        values = np.asarray(values, dtype=np.float64).reshape(times.size, rows_per_key, width)
        if path == "rotation":
            key_values = values[:, rows_per_key // 2, :]
            norms = np.linalg.norm(key_values, axis=1, keepdims=True)
            if np.any(norms == 0):
                raise ValueError(f"animation {name!r}: zero rotation quaternion")
            values[:, rows_per_key // 2, :] = key_values / norms
        flat = values.reshape(-1) if path == "weights" else values.reshape(-1, width)  # weights: SCALAR
        return self._add_channel(name, times, flat, interpolation, AnimationChannelTarget(node=int(node), path=path))

    def add_pointer_animation(self, name: str, pointer: str, times: Sequence[float], values: np.ndarray | Sequence,
                              interpolation: str = "LINEAR") -> int:
        """Animate the property at JSON ``pointer`` (KHR_animation_pointer, e.g.
        ``/extensions/KHR_lights_punctual/lights/0/intensity``): one row of ``values`` per key
        (one number for a scalar; booleans are written as unsigned bytes, as the extension has
        them); returns the animation index."""
        times = _key_times(name, times, interpolation)
        values = np.asarray(values)
        values = values.astype(np.uint8) if values.dtype == bool else values.astype(np.float64)
        flat = values.reshape(-1) if values.ndim == 1 or values.shape[-1] == 1 else values.reshape(-1, values.shape[-1])
        self._use_extension(POINTER_EXTENSION)
        target = AnimationChannelTarget(path="pointer", extensions={POINTER_EXTENSION: {"pointer": pointer}})
        return self._add_channel(name, times, flat, interpolation, target)

    def _add_channel(self, name: str, times: np.ndarray, values: np.ndarray, interpolation: str,
                     target: AnimationChannelTarget) -> int:
        """A sampler of ``times`` and ``values`` and its channel to ``target``, in the animation
        ``name`` (made on first use); returns the animation index."""
        input_accessor = self.add_accessor(times, with_bounds=True)
        output_accessor = self.add_accessor(values if values.dtype == np.uint8 else values.astype(np.float32))
        index = self._animations_by_name.get(name)
        if index is None:
            self.gltf.animations.append(Animation(name=name))
            index = self._animations_by_name[name] = len(self.gltf.animations) - 1
        animation = self.gltf.animations[index]
        animation.samplers.append(AnimationSampler(input=input_accessor, output=output_accessor,
                                                   interpolation=interpolation))
        animation.channels.append(AnimationChannel(sampler=len(animation.samplers) - 1, target=target))
        return index

    # -- scene ----------------------------------------------------------------------------------

    def set_scene_extras(self, extras: dict) -> None:
        """Merge ``extras`` into the default scene's extras (e.g. ``{"photonloom": {...}}``)."""
        json.dumps(extras)  # fail here, not at write time, on values JSON cannot hold
        self.gltf.scenes[0].extras.update(extras)

    def _use_extension(self, name: str) -> None:
        if name not in self.gltf.extensionsUsed:
            self.gltf.extensionsUsed.append(name)

    def _finished(self) -> GLTF2:
        """The glTF document with roots, lights and the single buffer filled in (buffer uri unset)."""
        children = [c for node in self.gltf.nodes for c in node.children]
        if len(children) != len(set(children)):
            raise ValueError("a node is listed as a child of more than one parent")
        self.gltf.scenes[0].nodes = [i for i in range(len(self.gltf.nodes)) if i not in set(children)]
        if self._lights:
            self.gltf.extensions[LIGHTS_EXTENSION] = {"lights": self._lights}
        self._pad_blob()
        self.gltf.buffers = [Buffer(byteLength=len(self._blob))] if self._blob else []
        return self.gltf

    def binary_blob(self) -> bytes:
        """The buffer's bytes (4-byte padded), as they go into the GLB BIN chunk or .bin file."""
        self._pad_blob()
        return bytes(self._blob)

    # -- output ---------------------------------------------------------------------------------

    def to_json(self, buffer_uri: str | None = None) -> str:
        """The glTF JSON; ``buffer_uri`` is the buffer's uri (None for GLB, where BIN holds it)."""
        gltf = self._finished()
        if gltf.buffers:
            gltf.buffers[0].uri = buffer_uri
        try:
            text = gltf.gltf_to_json(separators=(",", ":"), indent=None)
            if self._node_weights:  # pygltflib's Node has no ``weights`` (glTF §5.25): written here
                tree = json.loads(text)
                for node, weights in self._node_weights.items():
                    tree["nodes"][node]["weights"] = weights
                text = json.dumps(tree, separators=(",", ":"))
            return text
        finally:
            if gltf.buffers:
                gltf.buffers[0].uri = None

    def to_glb_bytes(self) -> bytes:
        """The scene as a GLB: 12-byte header, JSON chunk padded with spaces, BIN chunk padded with zeros."""
        json_chunk = self.to_json().encode("utf-8")
        json_chunk += b" " * (-len(json_chunk) % 4)
        bin_chunk = self.binary_blob()
        total = 12 + 8 + len(json_chunk) + (8 + len(bin_chunk) if bin_chunk else 0)
        out = bytearray(struct.pack("<4sII", b"glTF", 2, total))
        out += struct.pack("<I4s", len(json_chunk), b"JSON") + json_chunk
        if bin_chunk:
            out += struct.pack("<I4s", len(bin_chunk), b"BIN\0") + bin_chunk
        return bytes(out)

    def to_gltf_json_with_data_uri(self) -> str:
        """The scene as self-contained glTF JSON with the buffer as a base64 data URI."""
        uri = "data:application/octet-stream;base64," + base64.b64encode(self.binary_blob()).decode("ascii")
        return self.to_json(buffer_uri=uri)

    def write(self, path: str | Path, external_buffer: bool = False) -> Path:
        """Write ``path``: ``.glb`` as binary; ``.gltf`` as JSON with a data-URI buffer, or with
        ``external_buffer`` a ``<stem>.bin`` next to it. Returns the path written."""
        path = Path(path)
        suffix = path.suffix.lower()
        if suffix == ".glb":
            path.write_bytes(self.to_glb_bytes())
        elif suffix == ".gltf":
            if external_buffer:
                bin_path = path.with_suffix(".bin")
                bin_path.write_bytes(self.binary_blob())
                path.write_text(self.to_json(buffer_uri=bin_path.name))
            else:
                path.write_text(self.to_gltf_json_with_data_uri())
        else:
            raise ValueError(f"{path}: glTF files end in .glb or .gltf")
        return path
