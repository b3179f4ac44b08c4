"""Material model: glTF metallic/roughness factors mapped to diffuse, glossy or mirror behaviour.

Mapping (docs/03-conventions.md §2; written in the README too):

* ``baseColorFactor`` RGB is the Lambertian albedo (alpha ignored), times the ``baseColorTexture``
  and ``COLOR_0`` where present (pipeline/scene/shading.py, pipeline/scene/textures.py).
* ``metallic >= 0.5`` and ``roughness < 0.2``: an ideal **mirror** whose reflectance is the base colour.
* ``metallic >= 0.5`` and ``0.2 <= roughness < 0.6``: **glossy**, a normalised Phong lobe about the mirror
  direction with exponent ``2 / alpha^2 - 2``, ``alpha = roughness^2`` (the Blinn-Phong/Beckmann
  correspondence of Walter et al., EGSR 2007, §5.2), reflectance the base colour.
* everything else is **diffuse**.
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

if TYPE_CHECKING:
    import pygltflib

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

    @property
    def is_specular(self) -> bool:
        return self.kind in ("mirror", "glossy")

    @property
    def is_emissive(self) -> bool:
        return max(self.emission) > 0.0

    @property
    def phong_exponent(self) -> float:
        alpha = max(self.roughness, 1e-3) ** 2
        return 2.0 / (alpha * alpha) - 2.0


def classify(metallic: float, roughness: float) -> str:
    """``"mirror"``, ``"glossy"`` or ``"diffuse"`` from the glTF factors (see module docstring)."""
    if metallic >= METALLIC_THRESHOLD and roughness < MIRROR_ROUGHNESS:
        return "mirror"
    if metallic >= METALLIC_THRESHOLD and roughness < GLOSSY_ROUGHNESS:
        return "glossy"
    return "diffuse"


# The material properties KHR_animation_pointer may animate here, by their names under /materials/i/
ANIMATED_PROPERTIES = {"pbrMetallicRoughness/baseColorFactor": ("baseColorFactor", 4),
                       "emissiveFactor": ("emissiveFactor", 3),
                       "extensions/KHR_materials_emissive_strength/emissiveStrength": ("emissiveStrength", 1)}
MATERIAL_WIDTHS = {name: width for name, width in ANIMATED_PROPERTIES.values()}


def may_emit(material: Material, mat: pygltflib.Material, channels: dict | None) -> bool:
    """Whether ``material`` emits at some instant: at rest, or at any key of its animated
    ``channels`` (property name -> animation Sampler), where LINEAR and STEP values peak."""
    if material.is_emissive or not channels:
        return material.is_emissive
    times = sorted({float(t) for s in channels.values() for t in s.times})
    return any(animated_material(material, mat, {k: s.evaluate(t) for k, s in channels.items()}).is_emissive
               for t in times)


def any_emits(materials: list[Material], gltf_materials: list, channels: dict[int, dict], used: set[int]) -> bool:
    """Whether any of the ``used`` materials emits at some instant (:func:`may_emit`); the default
    material (past the file's) never does."""
    return any(may_emit(materials[m], gltf_materials[m], channels.get(m)) if m < len(gltf_materials)
               else materials[m].is_emissive for m in used)


def _factors(mat: pygltflib.Material) -> dict[str, np.ndarray]:
    """The file's values of the animatable properties (ANIMATED_PROPERTIES' short names)."""
    pbr = mat.pbrMetallicRoughness
    base = list(pbr.baseColorFactor) if pbr and pbr.baseColorFactor is not None else [1.0, 1.0, 1.0, 1.0]
    emissive = mat.emissiveFactor if mat.emissiveFactor is not None else [0.0, 0.0, 0.0]
    strength = (mat.extensions or {}).get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0)
    return {"baseColorFactor": np.asarray(base, float), "emissiveFactor": np.asarray(emissive, float),
            "emissiveStrength": np.asarray([strength], float)}


def animated_material(material: Material, mat: pygltflib.Material, values: dict[str, np.ndarray]) -> Material:
    """``material`` (built from the file's ``mat``) with the animated ``values`` of some of its
    ANIMATED_PROPERTIES at one instant; the others keep the file's values."""
    f = {**_factors(mat), **values}
    return replace(material, albedo=tuple(float(c) for c in np.clip(f["baseColorFactor"][:3], 0.0, 1.0)),
                   emission=tuple(float(c) for c in np.maximum(f["emissiveFactor"] * f["emissiveStrength"][0], 0.0)))


def material_from_gltf(mat: pygltflib.Material, index: int) -> Material:
    """Build a :class:`Material` from a pygltflib material."""
    pbr = mat.pbrMetallicRoughness
    f = _factors(mat)
    base = f["baseColorFactor"]
    metallic = float(pbr.metallicFactor) if pbr and pbr.metallicFactor is not None else 1.0
    roughness = float(pbr.roughnessFactor) if pbr and pbr.roughnessFactor is not None else 1.0
    emission = f["emissiveFactor"] * float(f["emissiveStrength"][0])
    return Material(
        name=mat.name or f"material{index}",
        albedo=tuple(float(c) for c in np.clip(base[:3], 0.0, 1.0)),
        kind=classify(metallic, roughness),
        roughness=roughness,
        emission=tuple(float(c) for c in emission),
        double_sided=bool(mat.doubleSided),
    )


DEFAULT_MATERIAL = Material("default", (0.8, 0.8, 0.8), "diffuse", 1.0, (0.0, 0.0, 0.0))
