"""Light culling of the compositor: bounding spheres of triangles and the cells a spot's cone or a
light's range may touch, so hits elsewhere skip that light at once (pipeline/frames/shading_tables.py
keeps them per frame, pipeline/frames/punctual_lights.py reads them)."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from pipeline.scene.lights import Light


def bounding_spheres(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centres and radii (slightly enlarged) of triangles given as (n, 3, 3) corners."""
    centre = corners.mean(axis=1)
    radius = np.sqrt(((corners - centre[:, None]) ** 2).sum(axis=2)).max(axis=1) * 1.001 + 1e-9
    return centre, radius


def light_reach(light: Light, centre: np.ndarray, radius: np.ndarray) -> np.ndarray | None:
    """(n,) bool: cells (bounding spheres) a spot's cone or a light's range may touch, so hits
    elsewhere skip that light at once; None when the light may reach everything."""
    if light.kind == "directional" or (light.kind == "point" and light.definition.range is None):
        return None
    v = centre - light.position
    dist = np.sqrt((v * v).sum(axis=1))
    reach = np.ones(len(centre), bool)
    if light.definition.range is not None:
        reach &= dist - radius < light.definition.range
    if light.kind == "spot":
        away = dist > radius
        cos_axis = np.clip((v[away] @ light.direction) / dist[away], -1.0, 1.0)
        gap = np.arccos(cos_axis) - np.arcsin(radius[away] / dist[away])
        reach[np.flatnonzero(away)[gap > light.definition.outer_cone]] = False
    return reach
