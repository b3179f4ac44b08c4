"""Area lights in the compositor: emissive triangles sampled by power and the sky sampled by
cosine-weighted directions, with shadow rays, at diffuse hits (glossy surfaces see them through
their lobe samples only, pipeline/frames/camera_paths.py).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from kernels.sampling import around
from pipeline.scene.environment import EnvironmentMap
from pipeline.scene.shading import triangle_points

from .punctual_lights import FAR
from .random_numbers import DIMS_PER_DEPTH, SKY_DIMS, SKY_DIMS_PER_DEPTH, uniform

if TYPE_CHECKING:
    from .camera_hits import CameraHits
    from .shading_tables import ShadingTables


def area_light(sh: ShadingTables, key: int, counter: np.ndarray, depth: int, hits: CameraHits,
               rays: dict[str, int], active: np.ndarray | None) -> np.ndarray:
    """Irradiance from emissive triangles at every hit: ``area_samples`` samples each, triangle
    chosen by power, point uniform on it (pbrt-v4 SampleUniformTriangle); E = L cos cos' / (d^2 pdf)."""
    p, facing, shade, tri = hits.points(), hits.facing(), hits.shading(), hits.tri
    total = np.zeros((len(p), 3), np.float32)
    base = 2 + depth * DIMS_PER_DEPTH + 2
    for s in range(sh.area_samples):
        u0, u1, u2 = (uniform(key, counter, base + 3 * s + j) for j in range(3))
        pick = np.minimum(np.searchsorted(sh.area_cdf, u0, side="right"), len(sh.area_cdf) - 1)
        su = np.sqrt(u1)
        b1, b2 = (su * (1.0 - u2)).astype(np.float32), (su * u2).astype(np.float32)
        y = triangle_points(np.take(sh.area_corners, pick, axis=0), b1, b2)
        lt = sh.area_tris[pick]
        delta = y - p
        dist2 = np.einsum("ij,ij->i", delta, delta)
        dist = np.sqrt(dist2)
        to_light = delta / np.maximum(dist, 1e-30)[:, None]
        cos_s = np.einsum("ij,ij->i", shade, to_light)
        cos_l = -np.einsum("ij,ij->i", np.take(sh.normals, lt, axis=0), to_light)  # front face only
        ok = (cos_s > 0) & (cos_l > 0) & (lt != tri)
        sel = np.flatnonzero(ok if active is None else ok & active)
        if not len(sel):
            continue
        # Both ends offset off their surfaces, towards each other, and the ray aimed from one to the
        # other (pbrt-v4's SpawnRayTo): a ray parallel to y - p would miss the shifted target
        origin = p[sel] + facing[sel] * sh.offsets[tri[sel]][:, None]  # the emitter is on the facing side
        target = y[sel] + np.take(sh.normals, lt[sel], axis=0) * sh.offsets[lt[sel]][:, None]
        span = target - origin
        reach = np.sqrt(np.einsum("ij,ij->i", span, span))
        d = np.ascontiguousarray(span / np.maximum(reach, 1e-30)[:, None], np.float32)
        blocked = sh.caster.occluded(origin, d, reach)
        rays["area"] += len(sel)
        sel = sel[~blocked]
        g = cos_s[sel] * cos_l[sel] / (dist2[sel] * sh.area_pdf[pick[sel]])
        if sh.surface.emission_varies:  # the emissive texture at the sampled point
            radiance = sh.surface.emission(lt[sel], b1[sel], b2[sel]).astype(np.float32)
        else:
            radiance = np.take(sh.emission, lt[sel], axis=0)
        total[sel] += g.astype(np.float32)[:, None] * radiance
    return total / np.float32(sh.area_samples)


def sky_light(sh: ShadingTables, key: int, counter: np.ndarray, depth: int, hits: CameraHits,
              rays: dict[str, int], active: np.ndarray | None) -> np.ndarray:
    """Irradiance from the sky at the hits (``active`` ones; None: all): ``sky_samples``
    cosine-weighted directions about the shading normal (pdf cos / pi), E = pi x mean of L(dir)
    over the unoccluded ones, so an open horizontal plane gets pi L exactly (no noise); directions
    below the geometric surface see nothing (as photon bounces, pipeline/scene/shading.py)."""
    rows = np.arange(len(hits.tri)) if active is None else np.flatnonzero(active)
    total = np.zeros((len(hits.tri), 3), np.float32)
    if not len(rows):
        return total
    facing, lobe = hits.facing(rows), hits.shading(rows).astype(np.float64)
    origin = hits.points(rows) + facing * sh.offsets[hits.tri[rows]][:, None]  # the sky is on the facing side
    c = counter[rows]
    base = SKY_DIMS + depth * SKY_DIMS_PER_DEPTH
    if isinstance(sh.sky, EnvironmentMap):
        return _environment_light(sh, (key, c, base), rows, (origin, facing, lobe), rays, total)
    for s in range(sh.sky_samples):
        u1, u2 = uniform(key, c, base + 2 * s), uniform(key, c, base + 2 * s + 1)
        d = np.ascontiguousarray(around(lobe, np.sqrt(u1), 2.0 * np.pi * u2), np.float32)
        free = ~sh.caster.occluded(origin, d, np.full(len(rows), FAR, np.float32))
        free &= np.einsum("ij,ij->i", d, facing) > 0
        rays["area"] += len(rows)
        total[rows[free]] += sh.sky.radiance(d[free])
    return total * np.float32(np.pi / sh.sky_samples)


def _environment_light(sh: ShadingTables, numbers: tuple, rows: np.ndarray, frame: tuple, rays: dict[str, int],
                       total: np.ndarray) -> np.ndarray:
    """:func:`sky_light` for an environment map: ``sky_samples`` directions by the map's importance
    (pipeline/scene/environment.py), E = mean of L cos / pdf over them (0 where occluded, below the
    surface or behind the shading normal). ``numbers``: (key, counters, first dimension);
    ``frame``: (ray origins, facing normals, shading normals) of the rows."""
    key, c, base = numbers
    origin, facing, lobe = frame
    env = sh.sky
    for s in range(sh.sky_samples):
        u = [uniform(key, c, base + 3 * s + k) for k in range(3)]  # the sky's dimensions, three a sample
        d, pdf = env.sample(*u)
        cos = np.einsum("ij,ij->i", d, lobe)
        d = np.ascontiguousarray(d, np.float32)
        free = (np.einsum("ij,ij->i", d, facing) > 0) & (cos > 0)
        free[free] = ~sh.caster.occluded(origin[free], d[free], np.full(int(free.sum()), FAR, np.float32))
        rays["area"] += len(rows)
        total[rows[free]] += (env.radiance(d[free]) * (cos[free] / pdf[free])[:, None]).astype(np.float32)
    return total / np.float32(sh.sky_samples)
