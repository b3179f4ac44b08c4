"""Per-frame shading tables of the compositor: what a hit looks up, per source triangle (material
kind, albedo, emission, normal, ray offset), the lights with their culling cells, the emitters'
sampling table and the illumination map per element (looked up on PoCL, kernels/surface.cl).
"""
from __future__ import annotations

import numpy as np

from kernels.scatter import KIND_CODE  # material kinds as the path loop codes them too
from kernels.surface import LookupCL
from pipeline.photons.raycast import RayCaster
from pipeline.scene import ElementMesh, FrameState
from pipeline.scene.shading import SurfaceShading

from .light_culling import bounding_spheres, light_reach


class ShadingTables:
    """Per-frame tables the wavefront reads, per source triangle (one gather per hit): kind,
    albedo, emission, normal; the lights, the emitters' sampling table and the map."""

    def __init__(self, state: FrameState, elements: ElementMesh | None, irradiance, caster: RayCaster,
                 area_samples: int, also_maps=()):
        mats = state.materials
        tri_mat = state.triangle_material.astype(np.int64)
        self.kind = np.array([KIND_CODE[m.kind] for m in mats], np.int8)[tri_mat]
        self.albedo = np.array([m.albedo for m in mats], np.float32)[tri_mat]
        self.exponent = np.array([m.phong_exponent for m in mats], np.float32)[tri_mat]
        self.ior = np.array([m.ior for m in mats], np.float64)[tri_mat]  # glass refracts by it
        self.emission = np.array([m.emission for m in mats], np.float32)[tri_mat]
        self.emissive = self.emission.max(axis=1) > 0
        self.any_emissive = bool(self.emissive.any())
        self.caster = caster
        self.surface = SurfaceShading(state, caster.normals)
        self.normals = caster.normals.astype(np.float32)
        self.corners = state.vertices[state.faces].astype(np.float32)  # (F, 3, 3), for hit points
        self.offsets = caster.offsets.astype(np.float32)  # shadow-ray origin offset per triangle (raycast.py)
        self.lights = state.lights
        self.sky = state.sky
        self.sky_samples = area_samples if state.sky is not None else 0
        # Light culling cells: elements when there is an element mesh (small, so a spot's cone
        # culls tightly), else source triangles; hits carry their cell id
        corners = (elements.element_positions(state) if elements is not None
                   else state.vertices.astype(np.float64)[state.faces])
        centre, radius = bounding_spheres(corners)
        self.reach = [light_reach(light, centre, radius) for light in state.lights]
        self.elements = elements
        self.element_irradiance = None  # (E, 3, 3) float32 [E0, E1 - E0, E2 - E0]: one gather a hit
        if irradiance is not None:
            self.element_irradiance = element_table(elements, irradiance)
        # Element and map irradiance of every hit, on PoCL (kernels/surface.cl)
        self.lookup = (LookupCL(elements.triangle_n, elements.triangle_offset[:-1], self.element_irradiance)
                       if elements is not None else None)
        # more maps seen along the same paths (pipeline/frames/camera_paths.py render_frame's also_maps)
        self.also = [LookupCL(elements.triangle_n, elements.triangle_offset[:-1], element_table(elements, m))
                     for m in also_maps]
        self.area_samples = area_samples if len(state.emissive_triangles) else 0
        if self.area_samples:
            tris = state.emissive_triangles.astype(np.int64)
            power = caster.triangle_area[tris] * self.surface.mean_emission(tris).mean(axis=1)
            self.area_tris = tris[power > 0]
            power = power[power > 0]
            if not len(self.area_tris):
                self.area_samples = 0
                return
            self.area_cdf = np.cumsum(power) / power.sum()
            self.area_cdf[-1] = 1.0
            self.area_pdf = power / power.sum() / caster.triangle_area[self.area_tris]  # per area
            self.area_corners = state.vertices.astype(np.float32)[state.faces[self.area_tris]]


def element_table(elements: ElementMesh, irradiance: np.ndarray) -> np.ndarray:
    """(E, 3, 3) float32 [E0, E1 - E0, E2 - E0] of a (V, 3) vertex map: one gather a hit."""
    e = np.asarray(irradiance, np.float64)[elements.element_vertices]
    return np.stack([e[:, 0], e[:, 1] - e[:, 0], e[:, 2] - e[:, 0]], axis=1).astype(np.float32)
