"""Emitters of a frame state: every light and emissive triangle, with its power and parameters.

Every emitter (a punctual light, or one emissive triangle) gets a selection weight equal to its
mean RGB flux (Light.power: point 4 pi I, spot 2 pi I x the fall-off integral, directional E x the
area of its projection map (below), emissive pi L A, with L averaged over an emissive texture;
each half of a sky, Sky.power, L x 2 pi x the disk's area). A sky half is a row of the light
tables after the frame's lights: its travel axis as the direction, its radiance as the radiant.
Photons go to emitters in proportion to that power, except that every *light* (a punctual light,
the triangles of one emissive material, or the sky) gets at least ``LIGHT_FLOOR`` / (number of
lights) of them: a lamp 1e6 times dimmer than another in a room of its own would otherwise get no
photon in most frames and, now and then, one of the bright light's weight, a firefly 1e6 times its
own light (tests/stress/test_lights.py). Weights are flux / probability, so the estimate stays
unbiased. The sampling itself is in kernels/emit.py (an OpenCL kernel and its NumPy twin); this
module turns a FrameState into their tables, and weights photons of textured emitters
(textured_emission_weights).
Records store photon weights; irradiance is sum(weight) / (N_emitted x area) (docs/05-estimators.md §1.1).

Directional lights emit from a projection map (Jensen, *Realistic Image Synthesis Using Photon
Mapping*, §5.1.3), not from the whole disk that covers the scene: the disk's square is cut into
``PROJECTION_GRID`` x ``PROJECTION_GRID`` cells, a ray along the light through each cell's centre
finds its first hit, and the light emits only from the cells whose ray hits a surface that can
take the photon (not a miss, not the back of a single-sided material, where pipeline/photons/tracing.py
absorbs it) and their eight neighbours (a margin of one cell: a surface narrower than a cell may
still fall between two centres). Its power, and so its share of the photons, is E times the
cells' area. Why: a sun over a closed building lights it through a skylight; emitted over the
whole disk, 97 % of ATRIUM's sun photons (90 % of all its photons) fell on the roof and walls from
outside, and a million photons left 210,000 indirect hits instead of 1,087,000
(docs/05-estimators.md §1.8). Photons outside the map could only be absorbed or lost, so the
estimate is the same; only its noise falls.
"""
from __future__ import annotations

import numpy as np

from kernels.emit import AREA, DIRECTIONAL, POINT, SKY, SPOT, EmissionTables
from kernels.philox import EMISSION_STREAM, uniforms
from kernels.sampling import orthonormal_basis
from pipeline.scene import FrameState
from pipeline.scene.environment import EnvironmentMap
from pipeline.scene.shading import SurfaceShading

from .raycast import RayCaster
from .sidedness import absorb_back_hits, one_sided_triangles

# Disk radius of directional lights, relative to the radius of the scene's bounds.
DISK_MARGIN = 1.01
# Share of the photons spread evenly over the lights (the rest by power); costs a scene of one
# dominant light at most this share of its photons.
LIGHT_FLOOR = 0.1
# Cells a side of a directional light's projection map (over the square around its disk)
PROJECTION_GRID = 256


def projection_map(caster: RayCaster, axis: np.ndarray, center: np.ndarray, radius: float,
                   one_sided: np.ndarray | None, grid: int = PROJECTION_GRID) -> tuple[np.ndarray, float]:
    """(M, 2) lower corners (a, b) of the cells a directional light travelling along ``axis`` emits
    from, in the basis kernels/sampling.orthonormal_basis(axis) about ``center``, and the cells' side.

    A cell is kept when the ray through its centre, from the disk's plane 1.05 ``radius`` upstream as
    kernels/emit.py starts photons, hits a triangle that is not single-sided (``one_sided`` (F,) bool,
    None: none is) or hits it on its front face; then its eight neighbours are kept too. No cell
    kept (the light misses the scene): every cell, the photons go where the disk's went."""
    axis = np.asarray(axis, np.float64)
    tt, ss = (v[0] for v in orthonormal_basis(axis[None]))
    h = 2.0 * radius / grid
    lower = np.arange(grid) * h - radius
    a, b = np.meshgrid(lower + 0.5 * h, lower + 0.5 * h, indexing="ij")
    origins = center + tt * a.reshape(-1, 1) + ss * b.reshape(-1, 1) - axis * (radius * 1.05)
    dirs = np.broadcast_to(axis.astype(np.float32), origins.shape)
    tri = caster.intersect(np.ascontiguousarray(origins, np.float32), np.ascontiguousarray(dirs))[0]
    takes = absorb_back_hits(tri, dirs, caster.normals, one_sided) >= 0
    hit = np.pad(takes.reshape(grid, grid), 1)
    keep = np.zeros((grid, grid), bool)
    for di in range(3):
        for dj in range(3):
            keep |= hit[di:di + grid, dj:dj + grid]
    if not keep.any():
        keep[:] = True
    i, j = np.nonzero(keep)
    return np.stack([lower[i], lower[j]], axis=1), h


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


def emission_tables(state: FrameState, caster: RayCaster) -> EmissionTables | None:
    """The emitter table (CDF of :func:`selection_probability`) and per-light parameters of a posed
    frame; None when nothing in it emits (every light off at this instant: an animated intensity or
    emission at 0), so that its photons carry nothing."""
    kinds, index, flux, group = [], [], [], []
    code = {"point": POINT, "spot": SPOT, "directional": DIRECTIONAL}
    radius = caster.radius * DISK_MARGIN
    one_sided = one_sided_triangles(state)
    light_cells = np.zeros((len(state.lights), 2), np.int64)
    cell_size = np.zeros(len(state.lights))
    cells = []
    for i, light in enumerate(state.lights):
        kinds.append(code[light.kind])
        index.append(i)
        if light.kind == "directional":  # its projection map's area, not the disk's
            corners, h = projection_map(caster, light.direction, caster.center.astype(np.float64), radius, one_sided)
            light_cells[i] = (sum(len(c) for c in cells), len(corners))
            cell_size[i] = h
            cells.append(corners)
            flux.append(light.radiant * (len(corners) * h * h))
        else:
            flux.append(light.power(radius))
        group.append(i)
    rows = [(li.position, li.direction, li.radiant, np.cos(li.definition.outer_cone),
             np.cos(li.definition.inner_cone)) for li in state.lights]
    if isinstance(state.sky, EnvironmentMap):  # one emitter; environment_photons gives its photons
        kinds.append(SKY)
        index.append(len(rows))
        flux.append(state.sky.power(radius))
        group.append(-1)
        rows.append((np.zeros(3), np.array([0.0, -1.0, 0.0]), np.zeros(3), np.cos(np.pi / 4), 1.0))  # unused
    elif state.sky is not None:
        for (radiance, axis), power in zip(state.sky.hemispheres, state.sky.power(radius)):
            kinds.append(SKY)
            index.append(len(rows))
            flux.append(power)
            group.append(-1)  # both halves of the sky are one light
            rows.append((np.zeros(3), axis, radiance, np.cos(np.pi / 4), 1.0))  # cones unused
    if len(state.emissive_triangles):
        tris = state.emissive_triangles
        radiance = SurfaceShading(state, caster.normals).mean_emission(tris)  # emissive textures: their mean
        kinds.extend([AREA] * len(tris))
        index.extend(tris.tolist())
        flux.extend(np.pi * radiance * caster.triangle_area[tris][:, None])
        group.extend(len(state.lights) + state.triangle_material[tris])
    flux = np.asarray(flux, dtype=np.float64).reshape(-1, 3)
    weight = flux.mean(axis=1)
    if not len(weight) or weight.sum() <= 0:
        return None
    cdf = np.cumsum(selection_probability(weight, np.asarray(group, np.int64)))
    cdf /= cdf[-1]
    cdf[-1] = 1.0
    return EmissionTables(
        cdf=cdf, prob=np.diff(np.concatenate([[0.0], cdf])), kind=np.asarray(kinds, np.int32),
        index=np.asarray(index, np.int64), flux=flux,
        light_pos=np.array([r[0] for r in rows], np.float64).reshape(-1, 3),
        light_dir=np.array([r[1] for r in rows], np.float64).reshape(-1, 3),
        light_rad=np.array([r[2] for r in rows], np.float64).reshape(-1, 3),
        cos_outer=np.array([r[3] for r in rows], np.float64),
        cos_inner=np.array([r[4] for r in rows], np.float64),
        corners=state.vertices[state.faces].reshape(-1, 9).astype(np.float32),
        normals=caster.normals, center=caster.center.astype(np.float64), radius=float(radius),
        epsilon=float(caster.epsilon), light_cells=light_cells, cell_size=cell_size,
        cells=np.concatenate(cells) if cells else np.zeros((0, 2)))


def environment_photons(table: EmissionTables, env: EnvironmentMap, photon: np.ndarray, emitter: np.ndarray,
                        key: tuple[int, int], emitted: tuple[np.ndarray, np.ndarray, np.ndarray]
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(origins, directions, weights) of photons with those of the environment map's emitter
    (pipeline/scene/environment.py) drawn again by its importance: a direction towards the map by
    :meth:`EnvironmentMap.sample`, travelling the other way from a point uniform on a disk of the
    table's radius facing it, 1.05 R upstream of the centre (kernels/emit.py's sky), weight
    L / pdf x pi R^2 over the emitter's selection probability. Their own Philox words (streams
    EMISSION_STREAM + 2 and + 3): the same photons on any worker."""
    origins, dirs, beta = (np.array(a) for a in emitted)
    rows = np.flatnonzero(table.kind[emitter] == SKY)
    if not len(rows):
        return origins, dirs, beta
    w = uniforms(photon[rows], EMISSION_STREAM + 2, key)
    w2 = uniforms(photon[rows], EMISSION_STREAM + 3, key)
    towards, pdf = env.sample(w[:, 0], w[:, 1], w[:, 2])
    travel = -towards
    tt, ss = orthonormal_basis(travel)
    r, a = table.radius * np.sqrt(w[:, 3]), 2.0 * np.pi * w2[:, 0]
    origins[rows] = (table.center + tt * (r * np.cos(a))[:, None] + ss * (r * np.sin(a))[:, None]
                     - travel * (table.radius * 1.05)).astype(np.float32)
    dirs[rows] = travel.astype(np.float32)
    scale = np.pi * table.radius * table.radius / (pdf * table.prob[emitter[rows]])
    beta[rows] = env.radiance(towards).astype(np.float64) * scale[:, None]
    return origins, dirs, beta


def textured_emission_weights(table: EmissionTables, surface: SurfaceShading, caster: RayCaster,
                              photon: np.ndarray, emitter: np.ndarray, key: tuple[int, int]) -> np.ndarray:
    """(n, 3) factors L(x) / L_mean of photons leaving textured emissive triangles (1 elsewhere).

    The emitter was chosen by its mean radiance (pi L_mean A); weighting a photon by the texture's
    radiance at its origin over that mean keeps the emitted flux pi integral(L dA) whatever the mean
    is. The origin's barycentrics come from the photon's own emission numbers (kernels/emit.py:
    b1 = sqrt(u1) (1 - u2), b2 = sqrt(u1) u2), so both emission backends get the same weights.
    """
    out = np.ones((len(photon), 3))
    area = np.flatnonzero(table.kind[emitter] == AREA)
    if not len(area):
        return out
    tri = table.index[emitter[area]]
    textured = np.isin(surface.tri_mat[tri], list(surface.emissive_textures))
    area, tri = area[textured], tri[textured]
    if not len(area):
        return out
    w = uniforms(photon[area], EMISSION_STREAM, key)
    su = np.sqrt(w[:, 1])
    radiance = surface.emission(tri, su * (1.0 - w[:, 2]), su * w[:, 2])
    mean = table.flux[emitter[area]] / (np.pi * caster.triangle_area[tri])[:, None]
    out[area] = np.divide(radiance, mean, out=np.zeros_like(radiance), where=mean > 0)
    return out
