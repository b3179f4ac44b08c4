"""Material textures: images decoded with OpenImageIO, samplers, ``KHR_texture_transform``.

A material's ``baseColorTexture`` or ``emissiveTexture`` becomes a :class:`Texture`: the image
decoded once when the scene is loaded (a worker loads each scene once, pipeline/scene/scene_cache.py, so
once per worker), converted from sRGB to linear (glTF 2.0 §3.9.2, §3.9.5: base-colour and emissive
textures are sRGB-encoded), with the sampler's wrap modes and filter and the texture transform.
:func:`sample` is a pure function over arrays: the photon tracer and the compositor both call it
(through pipeline/scene/shading.py), so texture colours are the same for photons and pixels.

Decisions: images are PNG, JPEG, WebP or KTX2 (``EXT_texture_webp``'s and ``KHR_texture_basisu``'s
images are read in place of the fallback; KTX2 is transcoded by Basis Universal's transcoder, any
format OpenImageIO reads is accepted); an image embedded in a bufferView or a data
URI is written to a temporary file for OpenImageIO, which reads files only from Python. There are
no mipmaps: minification uses the magnification filter (NEAREST or LINEAR, LINEAR when unset), and
the compositor's samples per pixel do the averaging. The alpha channel is kept for alpha masks
(pipeline/scene/cutouts.py); nothing is blended. Normal textures are read as linear data
(pipeline/scene/shading.py bends the shading normal with them), and so are metallic-roughness textures
(their blue and green channels scale the factors per hit: pipeline/scene/materials.py). Occlusion
textures are not applied: they are baked ambient occlusion, the shadowing of indirect light that the
photons compute themselves, so applying them would darken that light twice (pbrt-v4 and Mitsuba 3
do not read them either).
Spec: glTF 2.0 §5.26-§5.29 (textures, images, samplers); KHR_texture_transform README.
"""
from __future__ import annotations

import base64
import math
import os
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from urllib.parse import unquote

import numpy as np
import opengl_basisu
import pygltflib

from .gltf import GltfDocument

TEXTURE_TRANSFORM = "KHR_texture_transform"
NEAREST = 9728
LINEAR = 9729
REPEAT = 10497
CLAMP_TO_EDGE = 33071
MIRRORED_REPEAT = 33648
WRAP_NAMES = {REPEAT: "repeat", CLAMP_TO_EDGE: "clamp", MIRRORED_REPEAT: "mirror"}
_MIN_FILTERS = {NEAREST, LINEAR, 9984, 9985, 9986, 9987}  # the four mipmap modes sample level 0
_SUFFIX = {"image/png": ".png", "image/jpeg": ".jpg", "image/webp": ".webp"}
# A texture's WebP or KTX2 (Basis Universal) image, read in place of its PNG or JPEG fallback where it has one
WEBP, BASISU = "EXT_texture_webp", "KHR_texture_basisu"
KTX2_MAGIC = b"\xabKTX 20\xbb\r\n\x1a\n"
# Pixels an image may have (16 times 4096 x 2048): decoded to float RGB that is 1.6 GB; checked
# from the image's header before its pixels are decoded
MAX_TEXTURE_PIXELS = 1 << 27


@dataclass(frozen=True, eq=False)
class Texture:
    """One ``baseColorTexture``: linear RGB texels (H, W, 3) float32 and how to look them up."""

    image: np.ndarray = field(repr=False)
    image_index: int
    texcoord: int  # which TEXCOORD_n set the lookup uses
    wrap_s: int
    wrap_t: int
    nearest: bool  # NEAREST magnification filter, else bilinear
    transform: np.ndarray  # (2, 3) uv' = transform @ (u, v, 1) (KHR_texture_transform)
    alpha: np.ndarray | None = field(default=None, repr=False)  # (H, W) float32 alpha channel, None without one

    @property
    def has_transform(self) -> bool:
        return not np.array_equal(self.transform, np.eye(2, 3))

    @property
    def mean(self) -> np.ndarray:
        """Mean linear colour of the texels (3,)."""
        return self.image.reshape(-1, 3).mean(axis=0).astype(np.float64)


def texture_transform(ext: dict, where: str, doc: GltfDocument) -> np.ndarray:
    """The (2, 3) matrix T R S of KHR_texture_transform: offset, rotation (radians), scale."""
    try:
        ox, oy = (float(x) for x in ext.get("offset", (0.0, 0.0)))
        sx, sy = (float(x) for x in ext.get("scale", (1.0, 1.0)))
        r = float(ext.get("rotation", 0.0))
    except (TypeError, ValueError):
        raise doc.error("offset and scale must be 2 numbers, rotation a number", where) from None
    if not all(math.isfinite(x) for x in (ox, oy, sx, sy, r)):
        raise doc.error("offset, rotation and scale must be finite", where)
    return transform_matrix((ox, oy), r, (sx, sy))


def transform_matrix(offset: Sequence[float], rotation: float, scale: Sequence[float]) -> np.ndarray:
    """The (2, 3) matrix T R S of KHR_texture_transform from its ``offset``, ``rotation`` (radians)
    and ``scale`` (KHR_texture_transform's specification, its matrix)."""
    (ox, oy), r, (sx, sy) = (float(v) for v in offset), float(rotation), (float(v) for v in scale)
    c, s = math.cos(r), math.sin(r)
    translation = np.array([[1, 0, ox], [0, 1, oy], [0, 0, 1]], float)
    rotation = np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]], float)
    scale = np.diag([sx, sy, 1.0])
    return (translation @ rotation @ scale)[:2]


def base_color_texture(doc: GltfDocument, material_index: int, images: dict) -> Texture | None:
    """The material's ``baseColorTexture`` or None; ``images`` caches decoded images by (index, linear)."""
    pbr = doc.gltf.materials[material_index].pbrMetallicRoughness
    info = pbr.baseColorTexture if pbr is not None else None
    if info is None:
        return None
    return _texture(doc, info, f"materials[{material_index}].pbrMetallicRoughness.baseColorTexture", images)


def emissive_texture(doc: GltfDocument, material_index: int, images: dict) -> Texture | None:
    """The material's ``emissiveTexture`` (sRGB, multiplied by ``emissiveFactor``) or None."""
    info = doc.gltf.materials[material_index].emissiveTexture
    if info is None:
        return None
    return _texture(doc, info, f"materials[{material_index}].emissiveTexture", images)


def normal_texture(doc: GltfDocument, material_index: int, images: dict) -> Texture | None:
    """The material's ``normalTexture`` (tangent-space normals, linear: not sRGB) or None."""
    info = doc.gltf.materials[material_index].normalTexture
    if info is None:
        return None
    return _texture(doc, info, f"materials[{material_index}].normalTexture", images, linear=True)


def metallic_roughness_texture(doc: GltfDocument, material_index: int, images: dict) -> Texture | None:
    """The material's ``metallicRoughnessTexture`` (linear data: B metallic, G roughness) or None."""
    pbr = doc.gltf.materials[material_index].pbrMetallicRoughness
    info = pbr.metallicRoughnessTexture if pbr is not None else None
    if info is None:
        return None
    return _texture(doc, info, f"materials[{material_index}].pbrMetallicRoughness.metallicRoughnessTexture",
                    images, linear=True)


def transmission_texture(doc: GltfDocument, material_index: int, images: dict) -> Texture | None:
    """The material's ``KHR_materials_transmission`` ``transmissionTexture`` (linear: R scales the
    factor) or None."""
    ext = (doc.gltf.materials[material_index].extensions or {}).get("KHR_materials_transmission") or {}
    info = ext.get("transmissionTexture")
    if info is None:
        return None
    where = f"materials[{material_index}].extensions.KHR_materials_transmission.transmissionTexture"
    return _texture(doc, pygltflib.TextureInfo(index=info["index"], texCoord=info.get("texCoord"),
                                               extensions=info.get("extensions")), where, images, linear=True)


def _texture(doc: GltfDocument, info, where: str, images: dict, *, linear: bool = False) -> Texture:
    """A glTF textureInfo ``info`` (at ``where``) as a :class:`Texture`, checked; ``linear`` for
    data that are not colours (normal and metallic-roughness maps), which skip the sRGB decoding."""
    g = doc.gltf
    index = info.index
    if index is None or not 0 <= index < len(g.textures):
        raise doc.error(f"refers to a missing texture {index}", where + ".index")
    tex = g.textures[index]
    source, source_field = tex.source, f"textures[{index}].source"
    for name in (WEBP, BASISU):  # preferred to the fallback (EXT_texture_webp, KHR_texture_basisu)
        ext = (tex.extensions or {}).get(name)
        if isinstance(ext, dict) and ext.get("source") is not None:
            source, source_field = ext["source"], f"textures[{index}].extensions.{name}.source"
    if not isinstance(source, int) or isinstance(source, bool) or not 0 <= source < len(g.images):
        raise doc.error(f"refers to a missing image {source} (no supported image source)", source_field)
    wrap_s = wrap_t = REPEAT
    nearest = False
    if tex.sampler is not None:
        if not 0 <= tex.sampler < len(g.samplers):
            raise doc.error(f"refers to a missing sampler {tex.sampler}", f"textures[{index}].sampler")
        smp = g.samplers[tex.sampler]
        sf = f"samplers[{tex.sampler}]"
        wrap_s = REPEAT if smp.wrapS is None else smp.wrapS
        wrap_t = REPEAT if smp.wrapT is None else smp.wrapT
        for name, mode in (("wrapS", wrap_s), ("wrapT", wrap_t)):
            if mode not in WRAP_NAMES:
                raise doc.error(f"{mode} is not REPEAT, CLAMP_TO_EDGE or MIRRORED_REPEAT", f"{sf}.{name}")
        if smp.magFilter not in (None, NEAREST, LINEAR):
            raise doc.error(f"{smp.magFilter} is not NEAREST or LINEAR", f"{sf}.magFilter")
        if smp.minFilter is not None and smp.minFilter not in _MIN_FILTERS:
            raise doc.error(f"{smp.minFilter} is not a glTF minification filter", f"{sf}.minFilter")
        nearest = smp.magFilter == NEAREST
    texcoord = int(info.texCoord or 0)
    transform = np.eye(2, 3)
    ext = (info.extensions or {}).get(TEXTURE_TRANSFORM)
    if ext is not None:
        if not isinstance(ext, dict):
            raise doc.error("must be an object", f"{where}.extensions.{TEXTURE_TRANSFORM}")
        transform = texture_transform(ext, f"{where}.extensions.{TEXTURE_TRANSFORM}", doc)
        if ext.get("texCoord") is not None:  # the extension may override the set
            texcoord = int(ext["texCoord"])
    if texcoord not in (0, 1):
        raise doc.error(f"TEXCOORD_{texcoord} is not supported (TEXCOORD_0 and _1 are)", where + ".texCoord")
    if (source, linear) not in images:
        images[source, linear] = decode_image(doc, source, linear=linear)
    rgb, alpha = images[source, linear]
    return Texture(rgb, source, texcoord, wrap_s, wrap_t, nearest, transform, alpha)


def _image_bytes(doc: GltfDocument, index: int) -> tuple[bytes, str | None]:
    """The encoded bytes of ``images[index]`` (bufferView, data URI or external file) and a suffix."""
    img = doc.gltf.images[index]
    where = f"images[{index}]"
    if img.bufferView is not None:
        views = doc.gltf.bufferViews
        if not 0 <= img.bufferView < len(views):
            raise doc.error(f"refers to a missing bufferView {img.bufferView}", where + ".bufferView")
        view = views[img.bufferView]
        if view.buffer is None or not 0 <= view.buffer < len(doc.buffers):
            raise doc.error(f"bufferViews[{img.bufferView}] refers to a missing buffer", where + ".bufferView")
        start, length = int(view.byteOffset or 0), int(view.byteLength or 0)
        data = doc.buffers[view.buffer]
        if start + length > len(data):
            raise doc.error(f"bufferViews[{img.bufferView}] runs past the end of its buffer", where + ".bufferView")
        return data[start:start + length], _SUFFIX.get(img.mimeType or "")
    uri = img.uri
    if not uri:
        raise doc.error("has neither a uri nor a bufferView", where)
    if uri.startswith("data:"):
        header, _, payload = uri.partition(",")
        if not header.endswith(";base64"):
            raise doc.error("data URI is not base64", where + ".uri")
        try:
            return base64.b64decode(payload, validate=True), _SUFFIX.get(header[5:].split(";")[0])
        except ValueError as err:
            raise doc.error(f"bad base64 data URI: {err}", where + ".uri") from None
    target = doc.path.parent / unquote(uri)
    try:
        return target.read_bytes(), target.suffix or None
    except OSError:
        raise doc.error(f"missing image file {uri!r}", where + ".uri") from None


def decode_image(doc: GltfDocument, index: int, *, linear: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """``images[index]`` as linear RGB float32 (H, W, 3), sRGB to linear unless ``linear`` (the
    values are data, as a normal map's are), and its alpha channel (H, W) (never sRGB-encoded) or
    None: decoded by OpenImageIO, or a KTX2 image (KHR_texture_basisu) by Basis Universal's
    transcoder (:func:`_transcode_ktx2`)."""
    import OpenImageIO as oiio  # heavy: only where images are read or written

    data, suffix = _image_bytes(doc, index)
    where = f"images[{index}]"
    if data[:12] == KTX2_MAGIC:
        pixels = _transcode_ktx2(doc, data, where)
        return _channels(pixels, linear)
    # OpenImageIO's Python binding reads files only: give it a private temporary one
    fd, name = tempfile.mkstemp(suffix=suffix or _sniff_suffix(data))
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        inp = oiio.ImageInput.open(name)
        if inp is None:
            raise doc.error(f"cannot decode the image: {oiio.geterror().strip() or 'unknown format'}", where)
        try:
            _check_size(doc, inp.spec().width, inp.spec().height, where)
            pixels = inp.read_image("float")
        finally:
            inp.close()
    finally:
        os.unlink(name)
    if pixels is None or pixels.ndim != 3 or pixels.shape[0] == 0 or pixels.shape[1] == 0:
        raise doc.error("the image holds no pixels", where)
    return _channels(pixels, linear)


def _check_size(doc: GltfDocument, width: int, height: int, where: str) -> None:
    if width * height > MAX_TEXTURE_PIXELS:
        raise doc.error(f"{width} x {height} pixels is more than the {MAX_TEXTURE_PIXELS:,} an image may have", where)


def _transcode_ktx2(doc: GltfDocument, data: bytes, where: str) -> np.ndarray:
    """A KTX2 image's first level as float RGBA (H, W, 4; RGB where it stores no alpha) in [0, 1]:
    its Basis Universal payload (ETC1S or UASTC, the codecs KHR_texture_basisu allows) transcoded
    to 8-bit RGBA by Binomial's transcoder (opengl_basisu; docs/16-libraries.md §6). The encoded
    values are returned as they are: whether they are sRGB is the texture slot's to say."""
    try:
        texture = opengl_basisu.open(bytes(data))
        _check_size(doc, texture.width, texture.height, where)
        image = texture.transcode(opengl_basisu.Target.RGBA8)
    except opengl_basisu.BasisuError as err:  # corrupt data, or a KTX2 without a Basis Universal payload
        raise doc.error(f"cannot transcode the KTX2 image: {err}", where) from None
    pixels = np.asarray(image.data, np.float32).reshape(texture.height, texture.width, 4) / 255.0
    return pixels if texture.has_alpha else pixels[:, :, :3]


def _channels(pixels: np.ndarray, linear: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """Decoded pixels (H, W, C) in [0, 1] as linear RGB float32 and alpha (or None)."""
    channels = pixels.shape[2]
    rgb = np.repeat(pixels[:, :, :1], 3, axis=2) if channels < 3 else pixels[:, :, :3]
    rgb = np.clip(rgb, 0.0, 1.0)
    alpha = np.clip(pixels[:, :, channels - 1], 0.0, 1.0).astype(np.float32) if channels in (2, 4) else None
    return (rgb if linear else srgb_to_linear(rgb)).astype(np.float32), alpha


def _sniff_suffix(data: bytes) -> str:
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return ".png"
    if data[:3] == b"\xff\xd8\xff":
        return ".jpg"
    if data[:4] == b"RIFF" and data[8:12] == b"WEBP":
        return ".webp"
    return ".img"


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """The sRGB electro-optical transfer function (IEC 61966-2-1)."""
    c = np.asarray(c, np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _wrap(i: np.ndarray, n: int, mode: int) -> np.ndarray:
    if mode == CLAMP_TO_EDGE:
        return np.clip(i, 0, n - 1)
    if mode == MIRRORED_REPEAT:
        m = np.mod(i, 2 * n)
        return np.where(m < n, m, 2 * n - 1 - m)
    return np.mod(i, n)


def sample(texture: Texture, uv: np.ndarray) -> np.ndarray:
    """Linear RGB (n, 3) float64 of ``texture`` at texture coordinates ``uv`` (n, 2), after its
    transform. (0, 0) is the image's first (top-left) texel's corner, as glTF defines it."""
    uv = np.asarray(uv, np.float64)
    uv = uv @ texture.transform[:, :2].T + texture.transform[:, 2]
    img = texture.image
    h, w = img.shape[:2]
    x, y = uv[:, 0] * w, uv[:, 1] * h
    if texture.nearest:
        ix = _wrap(np.floor(x).astype(np.int64), w, texture.wrap_s)
        iy = _wrap(np.floor(y).astype(np.int64), h, texture.wrap_t)
        return img[iy, ix].astype(np.float64)
    x, y = x - 0.5, y - 0.5  # texel centres sit at half-integers
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    xa, xb = _wrap(x0, w, texture.wrap_s), _wrap(x0 + 1, w, texture.wrap_s)
    ya, yb = _wrap(y0, h, texture.wrap_t), _wrap(y0 + 1, h, texture.wrap_t)
    top = img[ya, xa] * (1 - fx) + img[ya, xb] * fx
    bottom = img[yb, xa] * (1 - fx) + img[yb, xb] * fx
    return (top * (1 - fy) + bottom * fy).astype(np.float64)
