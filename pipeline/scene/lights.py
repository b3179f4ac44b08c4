"""Punctual lights (``KHR_lights_punctual``) in world space, in radiometric units.

Units (docs/03-conventions.md §1): point and spot ``intensity x color`` is radiant intensity (W/sr); directional
``intensity x color`` is irradiance (W/m^2) on a surface facing it. No 683 lm/W or 4*pi factor.
Spot fall-off is the curve the KHR_lights_punctual specification recommends (smoothstep-free,
squared linear interpolation of the cosine between the outer and inner cone).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

LIGHT_KINDS = ("point", "spot", "directional")


@dataclass(frozen=True)
class LightDef:
    """A light as the file defines it, before it is placed by a node."""

    name: str
    kind: str
    color: tuple[float, float, float]
    intensity: float
    range: float | None = None
    inner_cone: float = 0.0
    outer_cone: float = np.pi / 4

    @property
    def radiant(self) -> np.ndarray:
        """RGB radiant intensity (point, spot) or irradiance (directional)."""
        return np.asarray(self.color, dtype=np.float64) * self.intensity


@dataclass(frozen=True)
class Light:
    """A light placed in the world at one instant."""

    definition: LightDef
    node: int
    position: np.ndarray  # world position (unused for directional)
    direction: np.ndarray  # unit world direction the light points to (node's -Z)

    @property
    def kind(self) -> str:
        return self.definition.kind

    @property
    def radiant(self) -> np.ndarray:
        return self.definition.radiant

    def spot_falloff(self, cos_angle: np.ndarray) -> np.ndarray:
        """Spot attenuation for rays at ``cos_angle`` to the axis (KHR_lights_punctual, "Spot")."""
        d = self.definition
        cos_outer = np.cos(d.outer_cone)
        cos_inner = np.cos(d.inner_cone)
        t = np.clip((cos_angle - cos_outer) / (cos_inner - cos_outer), 0.0, 1.0)
        return t * t

    def range_window(self, distance: np.ndarray) -> np.ndarray:
        """The specification's recommended range cut-off, clamp(1 - (d/range)^4, 0, 1)^2; 1 without range."""
        r = self.definition.range
        if r is None or self.kind == "directional":
            return np.ones_like(np.asarray(distance, dtype=np.float64))
        w = np.clip(1.0 - (np.asarray(distance, dtype=np.float64) / r) ** 4, 0.0, 1.0)
        return w * w

    def power(self, scene_radius: float) -> np.ndarray:
        """RGB radiant flux (W) leaving the light; a directional light's flux is its irradiance over
        the disk of ``scene_radius`` that covers the scene, which is what the photons carry."""
        d = self.definition
        if d.kind == "point":
            return 4.0 * np.pi * d.radiant
        if d.kind == "spot":
            # 2*pi * integral of the fall-off over cos(theta): full inside the inner cone, and
            # the squared ramp integrates to (cos_inner - cos_outer) / 3 between the cones
            ci, co = np.cos(d.inner_cone), np.cos(d.outer_cone)
            return 2.0 * np.pi * ((1.0 - ci) + (ci - co) / 3.0) * d.radiant
        return np.pi * scene_radius**2 * d.radiant

    def state(self) -> np.ndarray:
        """Numbers that fully describe the light's effect at this instant (for state keys)."""
        return np.concatenate([self.position, self.direction, self.radiant])


def light_def_from_gltf(raw: dict, index: int) -> LightDef:
    """Parse one ``KHR_lights_punctual`` light dictionary; raises ValueError on bad fields."""
    kind = raw.get("type")
    if kind not in LIGHT_KINDS:
        raise ValueError(f"type {kind!r} is not one of {', '.join(LIGHT_KINDS)}")
    color = tuple(float(c) for c in raw.get("color", (1.0, 1.0, 1.0)))
    intensity = float(raw.get("intensity", 1.0))
    rng = raw.get("range")
    if len(color) != 3 or not all(np.isfinite(color)) or min(color) < 0:
        raise ValueError(f"color {color} must be three finite non-negative numbers")
    if not np.isfinite(intensity) or intensity < 0:
        raise ValueError(f"intensity {intensity} must be finite and non-negative")
    if rng is not None and not float(rng) > 0:
        raise ValueError(f"range {rng} must be positive")
    spot = raw.get("spot", {}) if kind == "spot" else {}
    inner = float(spot.get("innerConeAngle", 0.0))
    outer = float(spot.get("outerConeAngle", np.pi / 4))
    if kind == "spot" and not (0 <= inner < outer <= np.pi / 2):
        raise ValueError(f"spot cone angles inner={inner} outer={outer} need 0 <= inner < outer <= pi/2")
    return LightDef(
        name=raw.get("name") or f"light{index}",
        kind=kind,
        color=color,
        intensity=intensity,
        range=float(rng) if rng is not None else None,
        inner_cone=inner,
        outer_cone=outer,
    )
