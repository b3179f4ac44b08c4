"""A uniform sky: an emitter at infinity of one radiance above the horizon and another below.

The sky surrounds the scene: radiance ``zenith`` (RGB, W/(m^2 sr) per channel, the units of
docs/03-conventions.md §1) from every direction of the upper hemisphere (world +Y, glTF's up) and ``ground``
from every direction of the lower one, as if the scene stood on an endless flat ground of that
brightness. Both the photon tracer (pipeline/photons/emission.py, kernels/emit.py: photons from a disk
covering the scene) and the compositor (pipeline/frames/area_lights.py: cosine-weighted shadow rays;
pipeline/frames/camera_paths.py: the background of rays that leave the scene) sample it.

Closed forms the tests check: a horizontal plane facing up, unoccluded, has irradiance
E = pi x zenith; facing down, pi x ground; with zenith = ground = L, every point on the outside of a
closed white (albedo 1) object has E = pi L, direct plus indirect (the furnace).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

UP = np.array([0.0, 1.0, 0.0])  # glTF 2.0 §3.4: +Y is up


@dataclass(frozen=True)
class Sky:
    """Uniform radiance above (``zenith``) and below (``ground``) the horizon, RGB."""

    zenith: tuple[float, float, float]
    ground: tuple[float, float, float]

    def __post_init__(self) -> None:
        for name in ("zenith", "ground"):
            v = np.asarray(getattr(self, name), np.float64)
            if v.shape != (3,) or not np.all(np.isfinite(v)) or v.min() < 0:
                raise ValueError(f"sky {name} {getattr(self, name)} must be three finite non-negative numbers")

    @property
    def hemispheres(self) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
        """(radiance, the direction photons from that half travel) for the upper and lower half."""
        return ((np.asarray(self.zenith, np.float64), -UP), (np.asarray(self.ground, np.float64), UP.copy()))

    def radiance(self, directions: np.ndarray) -> np.ndarray:
        """(n, 3) float32 radiance arriving from the sky along rays leaving in ``directions``."""
        up = np.asarray(directions)[:, 1] >= 0
        return np.where(up[:, None], np.asarray(self.zenith, np.float32), np.asarray(self.ground, np.float32))

    def power(self, radius: float) -> np.ndarray:
        """(2, 3) flux through a disk of ``radius`` from each half: L x 2 pi (the half's solid
        angle) x pi radius^2 (the disk every photon of that half crosses, kernels/emit.py)."""
        return np.stack([radiance * (2.0 * np.pi * np.pi * radius * radius) for radiance, _ in self.hemispheres])

    def state(self) -> np.ndarray:
        """Numbers that fully describe the sky (for state keys)."""
        return np.concatenate([self.zenith, self.ground]).astype(np.float64)


def direction_from(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """Unit world direction towards azimuth (degrees from +Z, the glTF front, towards +X) and
    elevation (degrees above the horizon)."""
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    return np.array([np.sin(az) * np.cos(el), np.sin(el), np.cos(az) * np.cos(el)])
