"""Material model: glTF metallic/roughness factors mapped to diffuse, glossy or mirror behaviour.

Mapping (docs/03-conventions.md §2; written in the README too):

* ``baseColorFactor`` RGB is the Lambertian albedo (its alpha cuts holes in MASK materials and
  lets rays through BLEND ones: pipeline/scene/cutouts.py), times the ``baseColorTexture``
  and ``COLOR_0`` where present (pipeline/scene/shading.py, pipeline/scene/textures.py).
* ``metallic >= 0.5`` and ``roughness < 0.2``: an ideal **mirror** whose reflectance is the base colour.
* ``metallic >= 0.5`` and ``0.2 <= roughness < 0.6``: **glossy**, a normalised Phong lobe about the mirror
  direction with exponent ``2 / alpha^2 - 2``, ``alpha = roughness^2`` (the Blinn-Phong/Beckmann
  correspondence of Walter et al., EGSR 2007, §5.2), reflectance the base colour.
* everything else is **diffuse**.
* A ``metallicRoughnessTexture`` multiplies the factors per hit (metallic by its blue channel,
  roughness by its green, linear data: glTF 2.0 §3.9.2), so one material may be diffuse at one texel and
  a mirror at the next: :func:`kind_codes` and :func:`phong_exponents` classify each hit
  (pipeline/scene/shading.py); :attr:`Material.kind` is then the kind at the factors alone.
* ``KHR_materials_transmission`` (thin-walled, pipeline/scene/cutouts.py): a hit lets the ray through
  with probability ``transmission x (1 - F)``, F Schlick's Fresnel term with ``F0 = ((ior - 1) /
  (ior + 1))^2`` (``KHR_materials_ior``, 1.5 by default: F0 0.04); otherwise it reflects as a smooth
  dielectric does, specularly: the kind is classified as if metallic were 1 (mirror below roughness
  0.2, glossy below 0.6). What passes is neither bent nor tinted, so clear glass is exact in how
  much it reflects and passes, coloured glass passes white.
* ``KHR_materials_volume`` with ``thicknessFactor > 0`` on a transmissive material makes it a solid
  **dielectric** instead (kernels/scatter.py, pipeline/frames/camera_paths.py): each hit reflects
  Fresnel's share and refracts the rest by Snell's law with the ior, entering or leaving by which
  side of its surface the ray meets; reflectance and transmittance are the base colour, roughness
  is not read (smooth glass). Shadow rays do not pass it: the light
  behind glass objects is their caustic, carried by the photons. Inside it, light keeps
  ``attenuationColor`` of itself over ``attenuationDistance`` (Beer's law, the extension's own
  definition), applied where a ray leaves the volume (pipeline/scene/shading.py).
* ``emissiveFactor x KHR_materials_emissive_strength`` (x the ``emissiveTexture``) is emitted radiance
  (front face only).
* ``doubleSided`` (glTF's default: false): a single-sided surface has no back. Photons that reach
  its back face are absorbed there, neither recorded nor reflected (pipeline/photons/tracing.py): the back of
  a wall or roof modelled as one inward-facing sheet is the outside of the building, and light
  falling on it must not reach the inner face's elements, which hold one irradiance for both sides.
* A primitive without a material gets :data:`DEFAULT_MATERIAL`, diffuse grey 0.8 (glTF's own default
  would be a white albedo of 1.0, which never loses energy in a closed room).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from kernels.scatter import KIND_CODE

from .textures import transform_matrix

if TYPE_CHECKING:
    import pygltflib

KINDS = tuple(sorted(KIND_CODE, key=KIND_CODE.get))  # by the code the bounce kernel knows each kind by
TRANSMISSION, IOR, VOLUME = "KHR_materials_transmission", "KHR_materials_ior", "KHR_materials_volume"
MIRROR_ROUGHNESS = 0.2
GLOSSY_ROUGHNESS = 0.6
METALLIC_THRESHOLD = 0.5


@dataclass(frozen=True)
class Material:
    name: str
    albedo: tuple[float, float, float]  # Lambertian albedo or specular reflectance, per channel
    kind: str  # "diffuse" | "glossy" | "mirror"
    roughness: float
    emission: tuple[float, float, float]  # emitted radiance, W/(m^2 sr) per channel
    base_color_texture: object = None  # pipeline.scene.textures.Texture multiplying albedo, or None
    emissive_texture: object = None  # a Texture multiplying emission (area lights), or None
    double_sided: bool = True  # glTF doubleSided; False: photons reaching the back face are absorbed
    normal_texture: object = None  # a Texture of tangent-space normals bending the shading normal, or None
    normal_scale: float = 1.0  # normalTexture.scale: multiplies the map's x and y
    alpha_mode: str = "OPAQUE"  # glTF alphaMode: MASK and BLEND let rays through (pipeline/scene/cutouts.py)
    alpha_cutoff: float = 0.5  # glTF alphaCutoff
    base_alpha: float = 1.0  # baseColorFactor's alpha, times the base-colour texture's alpha at a hit
    metallic: float = 0.0  # metallicFactor (with roughness, what ``kind`` is classified from)
    metallic_roughness_texture: object = None  # a linear Texture: B multiplies metallic, G roughness, per hit
    transmission: float = 0.0  # KHR_materials_transmission transmissionFactor (thin-walled, cutouts.py)
    ior: float = 1.5  # KHR_materials_ior: Fresnel's F0 of what is transmissive
    transmission_texture: object = None  # a linear Texture whose R multiplies ``transmission``, per hit
    thickness: float = 0.0  # KHR_materials_volume thicknessFactor: > 0 with transmission, a solid dielectric
    # KHR_materials_volume: light inside keeps attenuation_color after attenuation_distance (Beer's law)
    attenuation_color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    attenuation_distance: float = float("inf")

    @property
    def is_specular(self) -> bool:
        """Mirror, glossy or dielectric somewhere: at its factors, or at some texel of its
        metallic-roughness texture."""
        if self.kind in ("mirror", "glossy", "dielectric"):
            return True
        tex = self.metallic_roughness_texture
        return tex is not None and bool(np.any(kind_codes(self.metallic * tex.image[..., 2],
                                                          self.roughness * tex.image[..., 1]) != 0))

    @property
    def is_emissive(self) -> bool:
        return max(self.emission) > 0.0

    def state(self) -> np.ndarray:
        """Numbers that fully describe what the material does at one instant (for state keys)."""
        transforms = [t.transform.ravel() for t in (self.base_color_texture, self.emissive_texture) if t is not None]
        textured = [[self.metallic]] if self.metallic_roughness_texture is not None else []  # kind says it otherwise
        passing = ([[self.transmission, self.ior, self.thickness, *self.attenuation_color, self.attenuation_distance]]
                   if self.transmission > 0 else [])
        return np.concatenate([self.albedo, self.emission, [KINDS.index(self.kind), self.roughness, self.base_alpha,
                                                         self.alpha_cutoff],
                               *transforms, *textured, *passing])

    @property
    def f0(self) -> float:
        """Fresnel reflectance at normal incidence, ``((ior - 1) / (ior + 1))^2`` (KHR_materials_ior; 1 at ior 0)."""
        return 1.0 if self.ior == 0 else ((self.ior - 1.0) / (self.ior + 1.0)) ** 2

    @property
    def phong_exponent(self) -> float:
        alpha = max(self.roughness, 1e-3) ** 2
        return 2.0 / (alpha * alpha) - 2.0


def classify(metallic: float, roughness: float) -> str:
    """``"mirror"``, ``"glossy"`` or ``"diffuse"`` from the glTF factors (see module docstring)."""
    return KINDS[int(kind_codes(np.float64(metallic), np.float64(roughness)))]


def _kind(metallic: float, roughness: float, transmission: float, thickness: float, ior: float) -> str:
    """A material's kind: a solid dielectric where it transmits through a volume, else as
    :func:`classify` says, with metallic taken as 1 where it transmits (a smooth dielectric's
    reflection is specular; see the module docstring)."""
    if transmission > 0 and thickness > 0 and ior != 0:  # ior 0: KHR_materials_ior's perfect mirror
        return "dielectric"
    return classify(1.0 if transmission > 0 else metallic, roughness)


def kind_codes(metallic: np.ndarray, roughness: np.ndarray) -> np.ndarray:
    """Each point's kind as its index in :data:`KINDS` (0 diffuse, 1 mirror, 2 glossy), from its
    metallic and roughness values (the module docstring's thresholds)."""
    metal = np.asarray(metallic) >= METALLIC_THRESHOLD
    roughness = np.asarray(roughness)
    return np.where(metal & (roughness < MIRROR_ROUGHNESS), 1,
                    np.where(metal & (roughness < GLOSSY_ROUGHNESS), 2, 0)).astype(np.int8)


def phong_exponents(roughness: np.ndarray) -> np.ndarray:
    """float64 Phong exponents ``2 / alpha^2 - 2``, ``alpha = roughness^2``, per point (the
    module docstring's correspondence; :attr:`Material.phong_exponent` for a whole material)."""
    alpha = np.maximum(np.asarray(roughness, np.float64), 1e-3) ** 2
    return 2.0 / (alpha * alpha) - 2.0


# The material properties KHR_animation_pointer may animate here, by their pointers under
# /materials/i/: (short name, values a key holds)
ANIMATED_PROPERTIES = {"pbrMetallicRoughness/baseColorFactor": ("baseColorFactor", 4),
                       "pbrMetallicRoughness/metallicFactor": ("metallicFactor", 1),
                       "pbrMetallicRoughness/roughnessFactor": ("roughnessFactor", 1),
                       "emissiveFactor": ("emissiveFactor", 3),
                       "extensions/KHR_materials_emissive_strength/emissiveStrength": ("emissiveStrength", 1),
                       "alphaCutoff": ("alphaCutoff", 1),
                       "extensions/KHR_materials_transmission/transmissionFactor": ("transmissionFactor", 1)}
# A texture's KHR_texture_transform (a scrolling or turning texture), per texture slot
TEXTURE_SLOTS = {"baseColorTexture": "pbrMetallicRoughness/baseColorTexture", "emissiveTexture": "emissiveTexture"}
_TEXTURE_FIELDS = {"baseColorTexture": "base_color_texture", "emissiveTexture": "emissive_texture"}  # on Material
for _slot, _where in TEXTURE_SLOTS.items():
    for _part, _width in (("offset", 2), ("rotation", 1), ("scale", 2)):
        ANIMATED_PROPERTIES[f"{_where}/extensions/KHR_texture_transform/{_part}"] = (f"{_slot}.{_part}", _width)
MATERIAL_WIDTHS = {name: width for name, width in ANIMATED_PROPERTIES.values()}
# Properties whose keys must not be negative (texture offsets, rotations and scales may be)
NON_NEGATIVE = frozenset({"baseColorFactor", "metallicFactor", "roughnessFactor", "emissiveFactor",
                          "emissiveStrength", "alphaCutoff", "transmissionFactor"})


def _at_keys(material: Material, mat: pygltflib.Material, channels: dict):
    """``material`` at every key time of its animated ``channels``, where LINEAR and STEP values peak."""
    times = sorted({float(t) for s in channels.values() for t in s.times})
    return (animated_material(material, mat, {k: s.evaluate(t) for k, s in channels.items()}) for t in times)


def may_emit(material: Material, mat: pygltflib.Material, channels: dict | None) -> bool:
    """Whether ``material`` emits at some instant: at rest, or at any key of its animated
    ``channels`` (property name -> animation Sampler)."""
    if material.is_emissive or not channels:
        return material.is_emissive
    return any(m.is_emissive for m in _at_keys(material, mat, channels))


def may_reflect(material: Material, mat: pygltflib.Material, channels: dict | None) -> bool:
    """Whether ``material`` is a mirror or glossy at some instant (its metallic and roughness animated)."""
    if material.is_specular or not channels:
        return material.is_specular
    return any(m.is_specular for m in _at_keys(material, mat, channels))


def any_emits(materials: list[Material], gltf_materials: list, channels: dict[int, dict], used: set[int]) -> bool:
    """Whether any of the ``used`` materials emits at some instant (:func:`may_emit`); the default
    material (past the file's) never does."""
    return any(may_emit(materials[m], gltf_materials[m], channels.get(m)) if m < len(gltf_materials)
               else materials[m].is_emissive for m in used)


def texture_info(mat: pygltflib.Material, slot: str) -> pygltflib.TextureInfo | None:
    """The file's textureInfo of a TEXTURE_SLOTS ``slot`` of ``mat``, or None."""
    if slot == "baseColorTexture":
        return mat.pbrMetallicRoughness.baseColorTexture if mat.pbrMetallicRoughness is not None else None
    return mat.emissiveTexture


def _texture_transforms(mat: pygltflib.Material) -> dict[str, np.ndarray]:
    """The file's KHR_texture_transform offset, rotation and scale of each texture slot."""
    out = {}
    for slot in TEXTURE_SLOTS:
        info = texture_info(mat, slot)
        ext = ((getattr(info, "extensions", None) or {}).get("KHR_texture_transform") or {}) if info else {}
        out[f"{slot}.offset"] = np.asarray(ext.get("offset", (0.0, 0.0)), float)
        out[f"{slot}.rotation"] = np.asarray([ext.get("rotation", 0.0)], float)
        out[f"{slot}.scale"] = np.asarray(ext.get("scale", (1.0, 1.0)), float)
    return out


def _factors(mat: pygltflib.Material) -> dict[str, np.ndarray]:
    """The file's values of the animatable properties (ANIMATED_PROPERTIES' short names)."""
    pbr = mat.pbrMetallicRoughness
    base = list(pbr.baseColorFactor) if pbr and pbr.baseColorFactor is not None else [1.0, 1.0, 1.0, 1.0]
    base += [1.0] * (4 - len(base))  # an RGB factor is opaque
    metallic = pbr.metallicFactor if pbr and pbr.metallicFactor is not None else 1.0
    roughness = pbr.roughnessFactor if pbr and pbr.roughnessFactor is not None else 1.0
    emissive = mat.emissiveFactor if mat.emissiveFactor is not None else [0.0, 0.0, 0.0]
    extensions = mat.extensions or {}
    strength = extensions.get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0)
    transmission = extensions.get(TRANSMISSION, {}).get("transmissionFactor", 0.0)
    ior = extensions.get(IOR, {}).get("ior", 1.5)
    volume = extensions.get(VOLUME, {})
    thickness = volume.get("thicknessFactor", 0.0)
    return {"baseColorFactor": np.asarray(base, float), "metallicFactor": np.asarray([metallic], float),
            "roughnessFactor": np.asarray([roughness], float), "emissiveFactor": np.asarray(emissive, float),
            "emissiveStrength": np.asarray([strength], float),
            "alphaCutoff": np.asarray([mat.alphaCutoff if mat.alphaCutoff is not None else 0.5], float),
            "transmissionFactor": np.asarray([transmission], float), "ior": np.asarray([ior], float),
            "thicknessFactor": np.asarray([thickness], float),
            "attenuationColor": np.asarray(volume.get("attenuationColor", [1.0, 1.0, 1.0]), float),
            "attenuationDistance": np.asarray([volume.get("attenuationDistance", np.inf)], float),
            **_texture_transforms(mat)}


def animated_material(material: Material, mat: pygltflib.Material, values: dict[str, np.ndarray]) -> Material:
    """``material`` (built from the file's ``mat``) with the animated ``values`` of some of its
    ANIMATED_PROPERTIES at one instant; the others keep the file's values."""
    f = {**_factors(mat), **values}
    metallic, roughness = float(f["metallicFactor"][0]), float(np.clip(f["roughnessFactor"][0], 0.0, 1.0))
    transmission = float(np.clip(f["transmissionFactor"][0], 0.0, 1.0))
    textures = {}
    for slot in TEXTURE_SLOTS:
        texture = getattr(material, _TEXTURE_FIELDS[slot])
        if texture is not None and any(k.startswith(slot + ".") for k in values):
            transform = transform_matrix(f[f"{slot}.offset"], float(f[f"{slot}.rotation"][0]), f[f"{slot}.scale"])
            textures[_TEXTURE_FIELDS[slot]] = replace(texture, transform=transform)
    return replace(material, albedo=tuple(float(c) for c in np.clip(f["baseColorFactor"][:3], 0.0, 1.0)),
                   base_alpha=float(np.clip(f["baseColorFactor"][3], 0.0, 1.0)),
                   alpha_cutoff=max(float(f["alphaCutoff"][0]), 0.0),
                   kind=_kind(metallic, roughness, transmission, float(f["thicknessFactor"][0]), float(f["ior"][0])),
                   roughness=roughness, metallic=metallic, transmission=transmission, ior=float(f["ior"][0]),
                   thickness=float(f["thicknessFactor"][0]),
                   attenuation_color=tuple(float(c) for c in f["attenuationColor"]),
                   attenuation_distance=float(f["attenuationDistance"][0]),
                   emission=tuple(float(c) for c in np.maximum(f["emissiveFactor"] * f["emissiveStrength"][0], 0.0)),
                   **textures)


def material_from_gltf(mat: pygltflib.Material, index: int) -> Material:
    """Build a :class:`Material` from a pygltflib material: its factors as :func:`animated_material`
    reads them (the file's values, :func:`_factors`), at no animated key."""
    scale = mat.normalTexture.scale if mat.normalTexture is not None else None
    bare = Material(name=mat.name or f"material{index}", albedo=(0.0, 0.0, 0.0), kind="diffuse", roughness=1.0,
                    emission=(0.0, 0.0, 0.0), double_sided=bool(mat.doubleSided),
                    normal_scale=1.0 if scale is None else float(scale), alpha_mode=mat.alphaMode or "OPAQUE")
    return animated_material(bare, mat, {})


DEFAULT_MATERIAL = Material("default", (0.8, 0.8, 0.8), "diffuse", 1.0, (0.0, 0.0, 0.0))
