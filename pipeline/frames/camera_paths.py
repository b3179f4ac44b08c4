"""The compositor's path loop: a frame as the mean of its pixels' camera paths.

``spp`` jittered camera rays per pixel, traced in wavefronts of :data:`CHUNK_RAYS` samples; at each
depth the hits are shaded (emitters seen from the front, diffuse direct light with
pipeline/frames/punctual_lights.py and pipeline/frames/area_lights.py plus the map, glossy highlights) and mirror
and glossy hits continue, up to ``max_depth`` reflections. workers/composite.py sums it up.

:func:`visible_adaptation` gives a frame's adaptation luminance L_wa (pipeline/frames/tonemap.py) from what
its camera sees: a low-resolution pass of these same paths, :data:`ADAPTATION_WIDTH` pixels across
at one sample a pixel, then the log-average luminance of the pixels that saw something. Occluded
surfaces do not count, and the samples are the same every frame (one fixed random key), so a scene
whose light and view do not change gets the same L_wa however its objects move before the background.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Sequence

import numpy as np

from kernels.camera import camera_rays_cl, image_plane
from kernels.sampling import around
from kernels.scatter import refract_or_reflect
from pipeline.frames.tonemap import image_adaptation
from pipeline.photons.raycast import RayCaster, caster_for
from pipeline.scene import ElementMesh, FrameState
from pipeline.scene.camera import Camera

from .area_lights import area_light, sky_light
from .camera_hits import CameraHits
from .map_hits import MapHitRecorder, MapHits
from .pixel_samples import sample_means
from .punctual_lights import punctual_light
from .random_numbers import DIMS_PER_DEPTH, frame_key, uniform
from .settings import RenderSettings
from .shading_tables import ShadingTables

CHUNK_RAYS = 1 << 14  # camera samples per wavefront: a working set two workers keep in the shared L3
RAY_KINDS = ("camera", "shadow", "area", "reflection")  # rays counted per kind (FrameImage.rays)


@dataclass
class FrameImage:
    """Linear layers (H, W, 3) float32, coverage (H, W) and the rays cast per kind."""

    beauty: np.ndarray
    direct: np.ndarray
    indirect: np.ndarray
    albedo: np.ndarray
    alpha: np.ndarray
    rays: dict = field(default_factory=dict)
    also_indirect: list = field(default_factory=list)  # indirect layers of ``also_maps``, same paths
    map_hits: MapHits | None = None  # where the paths read the map (``render_frame(record_hits=True)``)

    def also_beauty(self, i: int) -> np.ndarray:
        """The beauty layer ``also_maps[i]`` gives: the bits of a render with that map alone."""
        return self.direct + self.also_indirect[i]


@dataclass(frozen=True)
class CameraPaths:
    """The camera paths of one frame: ``spp`` jittered samples a pixel of a ``width`` x ``height``
    image, up to ``max_depth`` reflections, ``area_samples`` area-light (or sky) samples a diffuse
    hit, their random numbers keyed by (``seed``, ``frame``) (pipeline/frames/random_numbers.py)."""

    width: int
    height: int
    spp: int
    seed: int
    frame: int
    max_depth: int = 4
    area_samples: int = 2

    @classmethod
    def of(cls, settings: RenderSettings, seed: int, frame: int) -> CameraPaths:
        """The paths of ``frame`` as ``settings`` render it."""
        return cls(settings.width, settings.height, settings.spp, seed, frame, settings.reflection_depth,
                   settings.area_samples)

    @cached_property
    def key(self) -> int:
        """The 64-bit key of the paths' random numbers."""
        return frame_key(self.seed, self.frame)


def render_frame(state: FrameState, elements: ElementMesh | None, irradiance: np.ndarray | None,
                 paths: CameraPaths, *, caster: RayCaster | None = None, chunk_rays: int = CHUNK_RAYS,
                 also_maps: Sequence[np.ndarray] = (), record_hits: bool = False) -> FrameImage:
    """Render one frame along ``paths``; ``irradiance`` (V, 3) is the indirect map (None: no indirect light).

    ``also_maps``: more (V, 3) maps whose indirect layers come from the same camera paths
    (``FrameImage.also_indirect``): the paths never depend on the map, so each layer has the bits
    of its own render at the cost of one more map lookup a hit (the AQM's I1, I2 of §5.2.3).
    ``chunk_rays`` camera samples are traced together (memory bound); pixels do not depend on it.
    ``record_hits``: keep where the paths read the map (``FrameImage.map_hits``), so that any other
    map can light them later (pipeline/frames/map_hits.py)."""
    also_maps = list(also_maps)  # a list of maps or the rows of a (M, V, 3) stack
    if (also_maps or record_hits) and irradiance is None:
        raise ValueError("also_maps and record_hits need a first map")
    caster = caster or caster_for(state)
    sh = ShadingTables(state, elements, irradiance, caster, paths.area_samples, also_maps)
    record = MapHitRecorder() if record_hits else None
    return _frame(paths, 3 + len(also_maps), chunk_rays, record,
                  lambda counter, rays, out: trace_samples(state, sh, paths, counter, rays, out, record))


def render_exposure(state: FrameState, shutter_states: Sequence[FrameState], elements: ElementMesh | None,
                    irradiance: np.ndarray | None, paths: CameraPaths) -> FrameImage:
    """Render one frame along ``paths`` with motion blur: sample j of every pixel sees the scene and
    the camera of ``shutter_states[j]`` (``paths.spp`` states posed at pipeline/frames/shutter.py's
    instants). Where they all equal ``state`` (the same geometry, lights and camera: nothing moves
    while the shutter is open) it is :func:`render_frame`, to the bit."""
    slices = _shutter_slices(state, shutter_states, paths, (elements, irradiance))
    if slices is None:
        return render_frame(state, elements, irradiance, paths)
    # chunks of spp x CHUNK_RAYS samples: each instant then traces a wavefront as large as render_frame's
    return _frame(paths, 3, CHUNK_RAYS * paths.spp, None,
                  lambda counter, rays, out: _trace_shutter(slices, paths, counter, rays, out))


def _frame(paths: CameraPaths, n_layers: int, chunk_rays: int, record: MapHitRecorder | None, trace) -> FrameImage:
    """The frame's layers from ``trace(counter, rays, out)``, which adds the layers of the camera
    samples ``counter`` (whole pixels) into ``out`` (n_layers, n, 3) and returns their coverage:
    direct, indirect, albedo, then the indirect layers of more maps, as contiguous planes."""
    spp = paths.spp
    n_pixels = paths.width * paths.height
    layers = np.zeros((n_layers, n_pixels, 3), np.float32)
    alpha = np.zeros(n_pixels, np.float32)
    rays = dict.fromkeys(RAY_KINDS, 0)
    chunk_pixels = max(1, chunk_rays // spp)
    samples = None if spp == 1 else np.empty((n_layers, chunk_pixels * spp, 3), np.float32)
    for lo in range(0, n_pixels, chunk_pixels):
        hi = min(n_pixels, lo + chunk_pixels)
        counter = np.arange(lo * spp, hi * spp, dtype=np.int64)
        if spp == 1:  # samples are pixels: trace straight into the layers
            alpha[lo:hi] = trace(counter, rays, layers[:, lo:hi])
        else:  # mean over each pixel's samples (consecutive counters), in a fixed order
            out = samples[:, :len(counter)]
            out.fill(0)
            cover = trace(counter, rays, out)
            sample_means(out.reshape(n_layers, hi - lo, spp, 3), layers[:, lo:hi])
            alpha[lo:hi] = cover.reshape(hi - lo, spp).mean(axis=1)
    shape = (paths.height, paths.width, 3)
    direct, indirect, albedo, *also = (layers[i].reshape(shape) for i in range(n_layers))
    return FrameImage(direct + indirect, direct, indirect, albedo, alpha.reshape(shape[:2]), rays, also,
                      None if record is None else record.finish(paths.width, paths.height, spp))


def _shutter_slices(state: FrameState, shutter_states, paths: CameraPaths, maps: tuple):
    """[(state, tables)] of each sample index, tables shared by states with one state key; None
    when every state is ``state`` as the camera and the scene see it (nothing moves while the
    shutter is open, or there is no shutter). ``maps``: (elements, irradiance)."""
    if shutter_states is None:
        return None
    if len(shutter_states) != paths.spp:
        raise ValueError(f"shutter_states holds {len(shutter_states)} states for {paths.spp} samples a pixel")
    if all(s.state_key == state.state_key and _same_view(s.camera, state.camera) for s in shutter_states):
        return None
    elements, irradiance = maps
    tables = {}
    for s in shutter_states:
        if s.state_key not in tables:
            tables[s.state_key] = ShadingTables(s, elements, irradiance, caster_for(s), paths.area_samples)
    return [(s, tables[s.state_key]) for s in shutter_states]


def _same_view(a: Camera | None, b: Camera | None) -> bool:
    if a is None or b is None:
        return a is b
    return a.definition == b.definition and np.array_equal(a.to_world, b.to_world)


def _trace_shutter(slices, paths: CameraPaths, counter: np.ndarray, rays: dict[str, int], out: np.ndarray):
    """:func:`trace_samples` of the chunk ``counter`` (whole pixels) with sample j of each pixel
    traced in the scene and from the camera of ``slices[j]``; returns the coverage (n,)."""
    cover = np.zeros(len(counter), np.float32)
    j_of = counter % paths.spp
    primary = {}  # the chunk's camera rays by camera pose: computed once where only objects move
    for j, (state, sh) in enumerate(slices):
        sel = np.flatnonzero(j_of == j)
        part = np.zeros((out.shape[0], len(sel), 3), np.float32)
        cam = state.camera
        view = (cam.definition, cam.to_world.tobytes()) if cam is not None else None
        if view not in primary:
            primary[view] = camera_rays(cam, paths.key, int(counter[0]), len(counter), paths)
        origins, dirs = primary[view]
        cover[sel] = trace_samples(state, sh, paths, counter[sel], rays, part, None,
                                   (origins[sel], dirs[sel]))
        out[:, sel] = part
    return cover


def camera_rays(cam: Camera, key: int, c0: int, n: int, paths: CameraPaths) -> tuple[np.ndarray, np.ndarray]:
    """Origins and unit directions (n, 3) float32 of camera samples c0 .. c0 + n - 1, jittered by
    random dimensions 0 and 1: from the pinhole through the image (kernels/camera.cl), or, for an
    orthographic camera, parallel along its -Z from the image's points, ``ymag`` up and
    ``ymag x width / height`` across either side of its axis."""
    if not cam.definition.orthographic:
        dirs = camera_rays_cl(key, c0, n, paths.spp, paths.width, paths.height, cam.definition.yfov,
                              cam.to_world[:3, :3])
        return np.broadcast_to(cam.position.astype(np.float32), dirs.shape), dirs
    a, b = image_plane(key, c0, n, paths.spp, paths.width, paths.height)
    axes = cam.to_world[:3, :3] / np.linalg.norm(cam.to_world[:3, :3], axis=0)
    ymag = cam.definition.ymag
    across = np.outer(a * ymag * paths.width / paths.height, axes[:, 0])
    origins = cam.position + across + np.outer(b * ymag, axes[:, 1])
    return origins.astype(np.float32), np.broadcast_to((-axes[:, 2]).astype(np.float32), (n, 3))


def trace_samples(state: FrameState, sh: ShadingTables, paths: CameraPaths, counter: np.ndarray,
                  rays: dict[str, int], out: np.ndarray, record: MapHitRecorder | None = None,
                  primary: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Add direct, indirect and albedo (and the indirect layers of ``sh.also``) of the camera
    samples ``counter`` of ``paths`` into ``out`` (L, n, 3), zero on entry; returns their coverage (n,).
    ``record`` collects the hits that read the map. ``primary``: the samples' camera rays (origins,
    directions), when ``counter`` is not a run of consecutive samples (a shutter's slice)."""
    n = len(counter)
    cover = np.zeros(n, np.float32)
    key, max_depth = paths.key, paths.max_depth
    origins, dirs = primary if primary is not None else camera_rays(state.camera, key, int(counter[0]), n, paths)
    path = None  # sample index of every live ray; None while it is 0..n-1
    throughput = None  # None while it is all ones (camera rays)
    for depth in range(max_depth + 1):
        tri, u, v, t = sh.caster.intersect(origins, dirs)  # float32 as Embree gives them
        rays["camera" if depth == 0 else "reflection"] += len(tri)
        hit = tri >= 0
        if not hit.all():
            if sh.sky is not None:  # rays that leave the scene see the sky
                miss = np.flatnonzero(~hit)
                glow = sh.sky.radiance(dirs[miss])
                if throughput is not None:
                    glow = (glow * throughput[miss]).astype(np.float32)
                out[0, miss if path is None else path[miss]] += glow
            path = np.flatnonzero(hit) if path is None else path[hit]
            tri, u, v, t, dirs, origins = tri[hit], u[hit], v[hit], t[hit], dirs[hit], origins[hit]
            throughput = None if throughput is None else throughput[hit]
        if not len(tri):
            break
        hits = CameraHits(sh, tri, u, v, origins, dirs, t)
        kept = sh.surface.volume_transmittance(tri, dirs, t)  # light absorbed inside coloured glass
        if kept is not None:
            kept = kept.astype(np.float32)
            throughput = kept if throughput is None else throughput * kept
        if sh.surface.kind_varies:  # metallic-roughness textures: each hit's own kind and lobe
            kind, exponent = sh.surface.kinds(tri, u, v)
            exponent = exponent.astype(np.float32)  # as the table holds them
        else:
            kind, exponent = sh.kind[tri], None
        if sh.surface.varies:  # textures or vertex colours: the base colour at every hit
            rho = sh.surface.base_color(tri, u, v).astype(np.float32)
        else:
            rho = np.take(sh.albedo, tri, axis=0)  # np.take: rows of a table, much faster than fancy indexing
        # This depth's layers: ``out`` itself while rays and samples correspond one to one,
        # else scattered into it once
        direct_out = path is None and throughput is None
        acc = out if direct_out else np.zeros((out.shape[0], len(tri), 3), np.float32)
        if depth == 0:
            acc[2] = rho
            _put(cover, path, 1.0)

        # Emitters seen from their front face
        if sh.any_emissive:
            lit = np.flatnonzero(sh.emissive[tri] & (hits.cos_in() < 0))
            if len(lit):
                acc[0, lit] += (sh.surface.emission(tri[lit], u[lit], v[lit]).astype(np.float32)
                                if sh.surface.emission_varies else np.take(sh.emission, tri[lit], axis=0))

        # Diffuse: direct light with shadow rays, indirect from the map; the path ends. Shaded
        # over all hits (cheaper than gathering the diffuse ones when they are most of them):
        # other hits get no shadow rays and a zero diffuse albedo.
        diffuse = kind == 0
        if diffuse.any():
            active = None if diffuse.all() else diffuse
            e_direct = punctual_light(sh, hits, None, None, rays, active)
            if sh.area_samples:
                c = counter if path is None else counter[path]
                e_direct += area_light(sh, key, c, depth, hits, rays, active)
            if sh.sky_samples:
                c = counter if path is None else counter[path]
                e_direct += sky_light(sh, key, c, depth, hits, rays, active)
            scale = (rho if active is None else rho * diffuse[:, None]) * np.float32(1.0 / np.pi)
            acc[0] += scale * e_direct
            if sh.element_irradiance is not None:
                acc[1] += scale * hits.indirect
                for j, also in enumerate(hits.also_indirect):
                    acc[3 + j] += scale * also
                if record is not None:
                    record.add(counter if path is None else counter[path], tri, u, v, scale, throughput,
                               np.flatnonzero(diffuse))
            if active is None:
                if not direct_out:
                    _put_layers(out, path, acc if throughput is None else acc * throughput[None])
                break

        # Glossy: exact highlights of punctual lights
        glossy = np.flatnonzero(kind == 2)
        if len(glossy):
            mirror_g = hits.reflect(glossy)
            lobe = (mirror_g, sh.exponent[tri[glossy]] if exponent is None else exponent[glossy])
            acc[0, glossy] += rho[glossy] * punctual_light(sh, hits, glossy, lobe, rays, None)

        if not direct_out:
            _put_layers(out, path, acc if throughput is None else acc * throughput[None])

        # Mirror and glossy reflection and glass continue the path
        spec = np.flatnonzero(kind != 0)
        if depth == max_depth or not len(spec):
            break
        refl = hits.reflect(spec)
        weight = rho[spec]
        g = np.flatnonzero(kind[spec] == 2)
        if len(g):
            e = (sh.exponent[tri[spec[g]]] if exponent is None else exponent[spec[g]]).astype(np.float64)
            c = counter[spec[g] if path is None else path[spec[g]]]
            base = 2 + depth * DIMS_PER_DEPTH
            cos_a = uniform(key, c, base) ** (1.0 / (e + 1.0))  # pdf (e+1)/(2 pi) cos^e
            lobe_dir = around(refl[g].astype(np.float64), cos_a, 2.0 * np.pi * uniform(key, c, base + 1))
            cos_o = np.einsum("ij,ij->i", lobe_dir, hits.shading(spec[g]))
            # normalised Phong BRDF rho (e+2)/(2 pi) cos^e times cos_o over the pdf
            weight[g] *= (np.maximum(cos_o, 0.0) * (e + 2.0) / (e + 1.0))[:, None]
            refl[g] = lobe_dir
        through = np.zeros(len(spec), bool)  # refracted into or out of glass: leaves on the far side
        glass = np.flatnonzero(kind[spec] == 3)
        if len(glass):
            rows = spec[glass]
            c = counter[rows if path is None else path[rows]]
            through[glass], refl[glass] = refract_or_reflect(
                np.take(dirs, rows, axis=0).astype(np.float64), hits.shading(rows).astype(np.float64),
                -hits.cos_in(rows), np.take(sh.ior, tri[rows]), uniform(key, c, 2 + depth * DIMS_PER_DEPTH))
        # leaving below the geometric surface (shading normals) ends the path, as in the tracer
        side = np.einsum("ij,ij->i", refl, hits.facing(spec))
        keep = (weight.max(axis=1) > 0) & np.where(through, side < 0, side > 0)
        spec, refl, weight = spec[keep], refl[keep], weight[keep]
        throughput = weight if throughput is None else throughput[spec] * weight
        origins = sh.caster.offset_origins(hits.points(spec), tri[spec], refl).astype(np.float32)
        dirs, path = refl, (spec if path is None else path[spec])
    return cover


def _put_layers(target: np.ndarray, idx, value) -> None:
    """target[:, idx] += value for layers (L, n, 3); idx None means all samples in order."""
    if idx is None:
        target += value
    else:
        target[:, idx] += value


def _put(target: np.ndarray, idx, value) -> None:
    """target[idx] = value; idx None means all rows in order."""
    if idx is None:
        target[...] = value
    else:
        target[idx] = value


ADAPTATION_WIDTH = 64  # pixels across: ~3,000 camera rays, a few ms next to a frame's composite
ADAPTATION_KEY_FRAME = 0  # the random key of every frame's pass (frames count from 1: never a frame's own)


def adaptation_size(aspect: float, width: int = ADAPTATION_WIDTH) -> tuple[int, int]:
    """(width, height) of the pass for an image of ``aspect`` = width / height."""
    return width, max(1, int(round(width / float(aspect))))


def visible_adaptation(state: FrameState, elements: ElementMesh, indirect: np.ndarray, settings: RenderSettings,
                       seed: int) -> float:
    """L_wa (radiance units) of the frame ``state`` lit by the indirect map ``indirect`` (V, 3), as
    its camera sees it at the aspect, reflections and area samples of ``settings``: pixels whose paths
    saw nothing (no geometry, no sky) are left out."""
    w, h = adaptation_size(settings.width / settings.height)
    img = render_frame(state, elements, indirect, CameraPaths(w, h, 1, seed, ADAPTATION_KEY_FRAME,
                                                              settings.reflection_depth, settings.area_samples))
    seen = (img.alpha > 0) | (img.beauty.max(axis=-1) > 0)
    return image_adaptation(img.beauty, seen)
