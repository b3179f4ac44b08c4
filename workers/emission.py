"""Photon emission: choose lights in proportion to power and sample photon origins and directions.

Every emitter (a punctual light, or one emissive triangle) gets a selection weight equal to its
mean RGB flux. A photon's RGB *weight* is its sample's flux estimate divided by the selection
probability, so that ``sum(weights) / N`` estimates the scene's total emitted flux whatever N is.
Records store these weights; irradiance is ``sum(weight) / (N_emitted * area)`` (dept.md §1.1),
which lets batches of different sizes be merged by dividing by the total photons emitted.

Sampling (pbrt-v4 "Light Sources" and "Sampling Algorithms" chapters):
  point        uniform sphere,                        weight I * 4 pi
  spot         uniform in the outer cone's solid angle Omega, weight I * falloff(theta) * Omega
  directional  uniform on a disk of the scene's bounding radius R facing the light, weight E * pi R^2
  emissive     uniform on the triangle, cosine-weighted about its front normal, weight pi * L * A
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kernels.philox import EMISSION_STREAM, uniforms
from pipeline.scene import FrameState

from .raycast import RayCaster

POINT, SPOT, DIRECTIONAL, AREA = 0, 1, 2, 3


@dataclass
class EmitterTable:
    kind: np.ndarray  # (K,) emitter kind
    index: np.ndarray  # (K,) light index in state.lights, or global triangle for AREA
    flux: np.ndarray  # (K, 3) RGB flux
    cdf: np.ndarray  # (K,) cumulative selection probability

    @property
    def total_flux(self) -> np.ndarray:
        return self.flux.sum(axis=0)

    @property
    def probability(self) -> np.ndarray:
        return np.diff(np.concatenate([[0.0], self.cdf]))


def emitter_table(state: FrameState, caster: RayCaster) -> EmitterTable:
    kinds, index, flux = [], [], []
    code = {"point": POINT, "spot": SPOT, "directional": DIRECTIONAL}
    radius = caster.radius * 1.01
    for i, light in enumerate(state.lights):
        kinds.append(code[light.kind])
        index.append(i)
        flux.append(light.power(radius))
    if len(state.emissive_triangles):
        tris = state.emissive_triangles
        radiance = np.array([state.materials[m].emission for m in state.triangle_material[tris]])
        kinds.extend([AREA] * len(tris))
        index.extend(tris.tolist())
        flux.extend(np.pi * radiance * caster.triangle_area[tris][:, None])
    flux = np.asarray(flux, dtype=np.float64).reshape(-1, 3)
    weight = flux.mean(axis=1)
    if not len(weight) or weight.sum() <= 0:
        raise ValueError("the scene's lights emit no power")
    cdf = np.cumsum(weight) / weight.sum()
    cdf[-1] = 1.0
    return EmitterTable(np.asarray(kinds, np.int8), np.asarray(index, np.int64), flux, cdf)


def _orthonormal_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tangents (t, b) for unit normals (n, 3): Duff et al., JCGT 6(1) 2017, "Building an
    orthonormal basis, revisited"."""
    sign = np.where(n[:, 2] >= 0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=1)
    bt = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    return t, bt


def around(axis: np.ndarray, cos_theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Directions at polar angle acos(cos_theta) and azimuth phi about unit ``axis`` vectors."""
    sin_theta = np.sqrt(np.clip(1.0 - cos_theta**2, 0.0, 1.0))
    t, b = _orthonormal_basis(axis)
    return (t * (sin_theta * np.cos(phi))[:, None] + b * (sin_theta * np.sin(phi))[:, None]
            + axis * cos_theta[:, None])


def cosine_hemisphere(normals: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Cosine-weighted directions about unit ``normals`` (Malley's method)."""
    u1, u2 = rng.random(len(normals)), rng.random(len(normals))
    return around(normals, np.sqrt(1.0 - u1), 2.0 * np.pi * u2)


def emit(table: EmitterTable, state: FrameState, caster: RayCaster, photon: np.ndarray, key: tuple[int, int]):
    """Photons with indices ``photon``: origins (n, 3), unit directions (n, 3), RGB weights (n, 3),
    emitter ids (n,). Random numbers are Philox words of (photon, EMISSION_STREAM + j) under ``key``."""
    n = len(photon)
    w0 = uniforms(photon, EMISSION_STREAM, key)
    u4 = uniforms(photon, EMISSION_STREAM + 1, key)[:, 0]
    choice = np.minimum(np.searchsorted(table.cdf, w0[:, 0], side="right"), len(table.cdf) - 1)
    prob = table.probability[choice]
    origins = np.empty((n, 3))
    dirs = np.empty((n, 3))
    weights = np.empty((n, 3))
    u1, u2, u3 = w0[:, 1], w0[:, 2], w0[:, 3]
    kind = table.kind[choice]

    for k in (POINT, SPOT, DIRECTIONAL, AREA):
        sel = np.flatnonzero(kind == k)
        if not len(sel):
            continue
        src = table.index[choice[sel]]
        if k == AREA:
            tri = state.vertices.astype(np.float64)[state.faces[src]]
            su = np.sqrt(u1[sel])
            b1, b2 = su * (1 - u2[sel]), su * u2[sel]  # uniform on the triangle (pbrt-v4 SampleUniformTriangle)
            p = (1 - b1 - b2)[:, None] * tri[:, 0] + b1[:, None] * tri[:, 1] + b2[:, None] * tri[:, 2]
            normal = caster.normals[src]
            d = around(normal, np.sqrt(1.0 - u3[sel]), 2.0 * np.pi * u4[sel])
            origins[sel] = p + normal * caster.epsilon
            dirs[sel] = d
            weights[sel] = table.flux[choice[sel]]
            continue
        for light_index in np.unique(src):
            light = state.lights[light_index]
            one = sel[src == light_index]
            m = len(one)
            if k == POINT:
                dirs[one] = around(np.tile([0.0, 0.0, 1.0], (m, 1)), 1.0 - 2.0 * u1[one], 2.0 * np.pi * u2[one])
                origins[one] = light.position
                weights[one] = light.radiant * 4.0 * np.pi
            elif k == SPOT:
                cos_outer = np.cos(light.definition.outer_cone)
                cos_t = 1.0 - u1[one] * (1.0 - cos_outer)
                dirs[one] = around(np.tile(light.direction, (m, 1)), cos_t, 2.0 * np.pi * u2[one])
                omega = 2.0 * np.pi * (1.0 - cos_outer)
                origins[one] = light.position
                weights[one] = light.radiant * (light.spot_falloff(cos_t) * omega)[:, None]
            else:  # DIRECTIONAL
                radius = caster.radius * 1.01
                r = radius * np.sqrt(u1[one])
                phi = 2.0 * np.pi * u2[one]
                axis = np.tile(light.direction, (m, 1))
                t, b = _orthonormal_basis(axis)
                disk = t * (r * np.cos(phi))[:, None] + b * (r * np.sin(phi))[:, None]
                origins[one] = caster.center + disk - axis * radius * 1.05
                dirs[one] = axis
                weights[one] = light.radiant * np.pi * radius**2
    weights /= prob[:, None]
    return origins, dirs, weights, choice
