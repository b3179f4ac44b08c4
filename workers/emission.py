"""Emitters of a frame state: every light and emissive triangle, with its power and parameters.

Every emitter (a punctual light, or one emissive triangle) gets a selection weight equal to its
mean RGB flux (Light.power: point 4 pi I, spot 2 pi I x the fall-off integral, directional E x the
area of the disk covering the scene, emissive pi L A). Photons go to emitters in proportion to that
power, except that every *light* (a punctual light, or the triangles of one emissive material)
gets at least ``LIGHT_FLOOR`` / (number of lights) of them: a lamp 1e6 times dimmer than another
in a room of its own would otherwise get no photon in most frames and, now and then, one of the
bright light's weight, a firefly 1e6 times its own light (tests/stress/test_lights.py). Weights
are flux / probability, so the estimate stays unbiased. The sampling itself is in kernels/emit.py
(an OpenCL kernel and its NumPy twin); this module turns a FrameState into their tables.
Records store photon weights; irradiance is sum(weight) / (N_emitted x area) (dept.md §1.1).
"""
from __future__ import annotations

import numpy as np

from kernels.emit import AREA, DIRECTIONAL, POINT, SPOT, EmissionTables
from pipeline.scene import FrameState

from .raycast import RayCaster

# Disk radius of directional lights, relative to the radius of the scene's bounds.
DISK_MARGIN = 1.01
# Share of the photons spread evenly over the lights (the rest by power); costs a scene of one
# dominant light at most this share of its photons.
LIGHT_FLOOR = 0.1


def selection_probability(weight: np.ndarray, group: np.ndarray) -> np.ndarray:
    """(K,) probability of each emitter: (1 - LIGHT_FLOOR) by power plus LIGHT_FLOOR shared evenly
    by the lights that emit (``group``: the light of each emitter), by power inside a light."""
    total = weight.sum()
    _, light = np.unique(group, return_inverse=True)
    light_power = np.bincount(light, weights=weight)
    emitting = light_power > 0
    share = np.where(emitting, LIGHT_FLOOR / emitting.sum(), 0.0)
    inside = np.divide(weight, light_power[light], out=np.zeros_like(weight), where=light_power[light] > 0)
    return (1.0 - LIGHT_FLOOR) * weight / total + share[light] * inside


def emission_tables(state: FrameState, caster: RayCaster) -> EmissionTables:
    """The emitter table (CDF of :func:`selection_probability`) and per-light parameters of a posed frame."""
    kinds, index, flux, group = [], [], [], []
    code = {"point": POINT, "spot": SPOT, "directional": DIRECTIONAL}
    radius = caster.radius * DISK_MARGIN
    for i, light in enumerate(state.lights):
        kinds.append(code[light.kind])
        index.append(i)
        flux.append(light.power(radius))
        group.append(i)
    if len(state.emissive_triangles):
        tris = state.emissive_triangles
        radiance = np.array([state.materials[m].emission for m in state.triangle_material[tris]])
        kinds.extend([AREA] * len(tris))
        index.extend(tris.tolist())
        flux.extend(np.pi * radiance * caster.triangle_area[tris][:, None])
        group.extend(len(state.lights) + state.triangle_material[tris])
    flux = np.asarray(flux, dtype=np.float64).reshape(-1, 3)
    weight = flux.mean(axis=1)
    if not len(weight) or weight.sum() <= 0:
        raise ValueError("the scene's lights emit no power")
    cdf = np.cumsum(selection_probability(weight, np.asarray(group, np.int64)))
    cdf /= cdf[-1]
    cdf[-1] = 1.0
    lights = state.lights
    return EmissionTables(
        cdf=cdf, prob=np.diff(np.concatenate([[0.0], cdf])), kind=np.asarray(kinds, np.int32),
        index=np.asarray(index, np.int64), flux=flux,
        light_pos=np.array([li.position for li in lights], np.float64).reshape(-1, 3),
        light_dir=np.array([li.direction for li in lights], np.float64).reshape(-1, 3),
        light_rad=np.array([li.radiant for li in lights], np.float64).reshape(-1, 3),
        cos_outer=np.array([np.cos(li.definition.outer_cone) for li in lights], np.float64),
        cos_inner=np.array([np.cos(li.definition.inner_cone) for li in lights], np.float64),
        corners=state.vertices[state.faces].reshape(-1, 9).astype(np.float32),
        normals=caster.normals, center=caster.center.astype(np.float64), radius=float(radius),
        epsilon=float(caster.epsilon))
