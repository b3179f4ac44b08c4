"""Final frames (§3, §6): ray-traced direct and specular light per pixel, indirect from the map.

For every pixel, ``spp`` jittered camera rays. At each hit:

* an emitter seen from its front face shows its emitted radiance;
* a **diffuse** surface gets direct light from every light with shadow rays (point, spot and
  directional exactly; emissive triangles by ``area_samples`` samples chosen by power, i.e. area x
  radiance) and indirect radiance rho/pi x E, E interpolated inside the hit element from its three
  vertex irradiances (the illumination map, workers/reconstruct.py); the path ends there;
* a **mirror** reflects, a **glossy** surface samples its normalised Phong lobe (the photon tracer's
  lobe, pipeline/scene/materials.py) and gets exact highlights of punctual lights; both continue up
  to ``max_depth`` reflections. Area lights reach glossy surfaces through the lobe samples only.

Layers per pixel (linear, radiance units): ``direct`` (emission and direct light, through the
specular chain), ``indirect`` (the map term), beauty = direct + indirect, and ``albedo`` of the
first surface hit. Ray counts per kind: camera, shadow (punctual lights), area (area-light shadow
rays), reflection. Scenes without specular materials cast no reflection rays, scenes without
emissive triangles no area rays.

Determinism: every random number is a hash of (seed, frame, pixel, sample, dimension)
(splitmix64, Steele et al., OOPSLA 2014), so pixels do not depend on chunking or workers.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.scene import ElementMesh, FrameState

from .emission import around
from .raycast import RayCaster, caster_for

CHUNK_RAYS = 1 << 17  # camera samples per wavefront: large Embree batches, bounded memory
RAY_KINDS = ("camera", "shadow", "area", "reflection")
_KIND = {"diffuse": 0, "mirror": 1, "glossy": 2}
_DIMS_PER_DEPTH = 16  # random dimensions per reflection depth: lobe (2) + area samples (3 each)
_FAR = 1e30  # shadow-ray length towards a directional light


# --- counter-based random numbers -------------------------------------------------------------
_M64 = (1 << 64) - 1


def _mix64(x: np.ndarray) -> np.ndarray:
    """splitmix64 finaliser on uint64 arrays (wrapping arithmetic)."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def frame_key(seed: int, frame: int) -> int:
    """64-bit key of (seed, frame) for :func:`uniform`."""
    k = _mix64(np.array([(seed * 0x9E3779B97F4A7C15 + 0x632BE59BD9B4E019) & _M64], np.uint64))
    return int(_mix64(k ^ np.uint64(frame & _M64))[0])


def uniform(key: int, counter: np.ndarray, dim: int) -> np.ndarray:
    """float64 in [0, 1) for each counter (pixel x spp + sample) and a dimension number."""
    x = _mix64(counter.astype(np.uint64) ^ np.uint64(key))
    x = _mix64(x + np.uint64((dim * 0x9E3779B97F4A7C15) & _M64))
    return (x >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))


# --- the frame ----------------------------------------------------------------------------------
@dataclass
class FrameImage:
    """Linear layers (H, W, 3) float32, coverage (H, W) and the rays cast per kind."""

    beauty: np.ndarray
    direct: np.ndarray
    indirect: np.ndarray
    albedo: np.ndarray
    alpha: np.ndarray
    rays: dict = field(default_factory=dict)


class _Shading:
    """Per-frame tables the wavefront reads: materials, normals, lights, emitters, the map."""

    def __init__(self, state: FrameState, elements: ElementMesh | None, irradiance, caster: RayCaster,
                 area_samples: int):
        mats = state.materials
        self.albedo = np.array([m.albedo for m in mats], np.float64)
        self.kind = np.array([_KIND[m.kind] for m in mats], np.int8)
        self.exponent = np.array([m.phong_exponent for m in mats], np.float64)
        self.emission = np.array([m.emission for m in mats], np.float64)
        self.emissive = self.emission.max(axis=1) > 0
        self.tri_mat = state.triangle_material.astype(np.int64)
        self.caster = caster
        self.normals = caster.normals
        self.lights = state.lights
        self.elements = elements
        self.irradiance = None if irradiance is None else np.asarray(irradiance, np.float64)
        self.area_samples = area_samples if len(state.emissive_triangles) else 0
        if self.area_samples:
            tris = state.emissive_triangles.astype(np.int64)
            power = caster.triangle_area[tris] * self.emission[self.tri_mat[tris]].mean(axis=1)
            self.area_tris = tris[power > 0]
            power = power[power > 0]
            self.area_cdf = np.cumsum(power) / power.sum()
            self.area_cdf[-1] = 1.0
            self.area_prob = power / power.sum()
            self.area_corners = state.vertices.astype(np.float64)[state.faces[self.area_tris]]
            if not len(self.area_tris):
                self.area_samples = 0


def camera_rays(state: FrameState, width: int, height: int, px: np.ndarray, py: np.ndarray):
    """World origins (3,) and unit directions (n, 3) through image points (px, py) in pixels,
    x right and y down from the top-left corner; the camera looks down -Z, +Y up, yfov vertical."""
    cam = state.camera
    tan_y = np.tan(cam.definition.yfov / 2.0)
    x = (2.0 * px / width - 1.0) * tan_y * (width / height)
    y = (1.0 - 2.0 * py / height) * tan_y
    rot = cam.to_world[:3, :3]
    rot = rot / np.linalg.norm(rot, axis=0)
    d = x[:, None] * rot[:, 0] + y[:, None] * rot[:, 1] - rot[:, 2]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return cam.position, d


def render_frame(state: FrameState, elements: ElementMesh | None, irradiance, *, width: int,
                 height: int, spp: int, seed: int, frame: int, max_depth: int = 4,
                 area_samples: int = 2, caster: RayCaster | None = None) -> FrameImage:
    """Render one frame; ``irradiance`` (V, 3) is the indirect map (None: no indirect light)."""
    caster = caster or caster_for(state)
    sh = _Shading(state, elements, irradiance, caster, area_samples)
    key = frame_key(seed, frame)
    n_pixels = width * height
    layers = np.zeros((4, n_pixels, 3), np.float32)  # direct, indirect, albedo, (alpha, -, -)
    rays = dict.fromkeys(RAY_KINDS, 0)
    chunk_pixels = max(1, CHUNK_RAYS // spp)
    for lo in range(0, n_pixels, chunk_pixels):
        hi = min(n_pixels, lo + chunk_pixels)
        counter = np.arange(lo * spp, hi * spp, dtype=np.int64)
        out = _trace_samples(state, sh, key, counter, spp, width, height, max_depth, rays)
        layers[:, lo:hi] = out.reshape(4, hi - lo, spp, 3).mean(axis=2)
    shape = (height, width, 3)
    direct, indirect, albedo = (layers[i].reshape(shape) for i in range(3))
    return FrameImage(direct + indirect, direct, indirect, albedo, layers[3, :, 0].reshape(shape[:2]),
                      rays)


def _trace_samples(state, sh: _Shading, key, counter, spp, width, height, max_depth, rays):
    """(4, n, 3) float64: direct, indirect, albedo and coverage of the samples ``counter``."""
    n = len(counter)
    out = np.zeros((4, n, 3))
    pixel = counter // spp
    px = pixel % width + uniform(key, counter, 0)
    py = pixel // width + uniform(key, counter, 1)
    origin, dirs = camera_rays(state, width, height, px, py)
    origins = np.broadcast_to(origin, dirs.shape)
    path = np.arange(n)  # sample index of every live ray
    throughput = None  # None: all ones (camera rays)
    for depth in range(max_depth + 1):
        tri, u, v, t = sh.caster.intersect(origins, dirs)
        rays["camera" if depth == 0 else "reflection"] += len(path)
        hit = tri >= 0
        if not hit.all():
            tri, u, v, t, dirs, path = tri[hit], u[hit], v[hit], t[hit], dirs[hit], path[hit]
            origins = origins[hit]
            throughput = None if throughput is None else throughput[hit]
        if not len(path):
            break
        points = origins + t[:, None] * dirs
        m = sh.tri_mat[tri]
        kind = sh.kind[m]
        rho = sh.albedo[m]
        normal = sh.normals[tri]
        cos_in = np.einsum("ij,ij->i", normal, dirs)
        facing = normal * np.where(cos_in < 0, 1.0, -1.0)[:, None]  # towards the viewer
        if depth == 0:
            out[2, path] = rho
            out[3, path] = 1.0

        def add(layer, sel, value):
            w = value if throughput is None else value * throughput[sel]
            out[layer, path[sel]] += w

        # Emitters seen from their front face
        lit = sh.emissive[m] & (cos_in < 0)
        if lit.any():
            sel = np.flatnonzero(lit)
            add(0, sel, sh.emission[m[sel]])

        # Diffuse: direct light with shadow rays, indirect from the map; the path ends
        diffuse = np.flatnonzero(kind == 0)
        if len(diffuse):
            p, f, tr = points[diffuse], facing[diffuse], tri[diffuse]
            e_direct = _punctual(sh, p, f, tr, None, rays)
            if sh.area_samples:
                e_direct += _area(sh, key, counter[path[diffuse]], depth, p, f, tr, rays)
            add(0, diffuse, rho[diffuse] / np.pi * e_direct)
            if sh.irradiance is not None:
                add(1, diffuse, rho[diffuse] / np.pi * _interpolate(sh, tr, u[diffuse], v[diffuse]))

        # Glossy: exact highlights of punctual lights
        glossy = np.flatnonzero(kind == 2)
        if len(glossy):
            mirror_g = dirs[glossy] - 2.0 * cos_in[glossy, None] * normal[glossy]
            lobe = (mirror_g, sh.exponent[m[glossy]])
            add(0, glossy, rho[glossy] * _punctual(sh, points[glossy], facing[glossy], tri[glossy],
                                                   lobe, rays))

        # Mirror and glossy reflection continue the path
        spec = np.flatnonzero(kind != 0)
        if depth == max_depth or not len(spec):
            break
        d = dirs[spec]
        refl = d - 2.0 * cos_in[spec, None] * normal[spec]
        weight = rho[spec]
        g = kind[spec] == 2
        if g.any():
            gi = np.flatnonzero(g)
            e = sh.exponent[m[spec[gi]]]
            c = counter[path[spec[gi]]]
            base = 2 + depth * _DIMS_PER_DEPTH
            cos_a = uniform(key, c, base) ** (1.0 / (e + 1.0))  # pdf (e+1)/(2 pi) cos^e
            lobe_dir = around(refl[gi], cos_a, 2.0 * np.pi * uniform(key, c, base + 1))
            cos_o = np.einsum("ij,ij->i", lobe_dir, facing[spec[gi]])
            # normalised Phong BRDF rho (e+2)/(2 pi) cos^e times cos_o over the pdf
            weight[gi] *= (np.maximum(cos_o, 0.0) * (e + 2.0) / (e + 1.0))[:, None]
            refl[gi] = lobe_dir
        keep = weight.max(axis=1) > 0
        spec, refl, weight = spec[keep], refl[keep], weight[keep]
        throughput = weight if throughput is None else throughput[spec] * weight
        origins = sh.caster.offset_origins(points[spec], tri[spec], refl)
        dirs, path = refl, path[spec]
    return out


def _interpolate(sh: _Shading, tri, u, v) -> np.ndarray:
    """Irradiance inside the hit element: barycentric blend of its three vertex values."""
    elem, b1, b2 = sh.elements.locate(tri, u, v)
    corners = sh.elements.element_vertices[elem]
    e = sh.irradiance
    return ((1.0 - b1 - b2)[:, None] * e[corners[:, 0]] + b1[:, None] * e[corners[:, 1]]
            + b2[:, None] * e[corners[:, 2]])


def _punctual(sh: _Shading, p, facing, tri, lobe, rays) -> np.ndarray:
    """Irradiance (lobe None) or glossy radiance over rho (lobe = (mirror dirs, exponents)) from
    every point, spot and directional light, with shadow rays."""
    total = np.zeros((len(p), 3))
    for light in sh.lights:
        if light.kind == "directional":
            to_light = np.broadcast_to(-light.direction, p.shape)
            dist = np.full(len(p), _FAR)
            scale = np.ones(len(p))
        else:
            delta = light.position - p
            dist = np.sqrt(np.einsum("ij,ij->i", delta, delta))
            to_light = delta / np.maximum(dist, 1e-30)[:, None]
            scale = light.range_window(dist) / np.maximum(dist, 1e-30) ** 2
            if light.kind == "spot":
                scale = scale * light.spot_falloff(-to_light @ light.direction)
        cos_s = np.einsum("ij,ij->i", facing, to_light)
        if lobe is not None:  # normalised Phong: (e+2)/(2 pi) cos^e(angle to the mirror direction)
            cos_r = np.maximum(np.einsum("ij,ij->i", lobe[0], to_light), 0.0)
            scale = scale * (lobe[1] + 2.0) / (2.0 * np.pi) * cos_r ** lobe[1]
        sel = np.flatnonzero((cos_s > 0) & (scale > 0))
        if not len(sel):
            continue
        d = np.ascontiguousarray(to_light[sel])
        origin = sh.caster.offset_origins(p[sel], tri[sel], d)
        blocked = sh.caster.occluded(origin, d, dist[sel] * (1.0 - 1e-5))
        rays["shadow"] += len(sel)
        sel = sel[~blocked]
        total[sel] += (scale[sel] * cos_s[sel])[:, None] * light.radiant
    return total


def _area(sh: _Shading, key, counter, depth, p, facing, tri, rays) -> np.ndarray:
    """Irradiance from emissive triangles: ``area_samples`` samples per point, triangle chosen by
    power, point uniform on it (pbrt-v4 SampleUniformTriangle); E = L cos cos' / (d^2 pdf)."""
    total = np.zeros((len(p), 3))
    base = 2 + depth * _DIMS_PER_DEPTH + 2
    for s in range(sh.area_samples):
        u0, u1, u2 = (uniform(key, counter, base + 3 * s + j) for j in range(3))
        pick = np.minimum(np.searchsorted(sh.area_cdf, u0, side="right"), len(sh.area_cdf) - 1)
        su = np.sqrt(u1)
        b1, b2 = su * (1.0 - u2), su * u2
        c = sh.area_corners[pick]
        y = (1.0 - b1 - b2)[:, None] * c[:, 0] + b1[:, None] * c[:, 1] + b2[:, None] * c[:, 2]
        lt = sh.area_tris[pick]
        delta = y - p
        dist2 = np.einsum("ij,ij->i", delta, delta)
        dist = np.sqrt(dist2)
        to_light = delta / np.maximum(dist, 1e-30)[:, None]
        cos_s = np.einsum("ij,ij->i", facing, to_light)
        cos_l = -np.einsum("ij,ij->i", sh.normals[lt], to_light)  # front face only
        sel = np.flatnonzero((cos_s > 0) & (cos_l > 0) & (lt != tri))
        if not len(sel):
            continue
        d = np.ascontiguousarray(to_light[sel])
        origin = sh.caster.offset_origins(p[sel], tri[sel], d)
        # stop short of the emitter itself: the length from the offset origin less 2 epsilon
        reach = np.sqrt(((y[sel] - origin) ** 2).sum(axis=1)) - 2.0 * sh.caster.epsilon
        blocked = sh.caster.occluded(origin, d, np.maximum(reach, 0.0))
        rays["area"] += len(sel)
        sel = sel[~blocked]
        pdf = sh.area_prob[pick[sel]] / sh.caster.triangle_area[lt[sel]]
        g = cos_s[sel] * cos_l[sel] / (dist2[sel] * pdf)
        total[sel] += g[:, None] * sh.emission[sh.tri_mat[lt[sel]]]
    return total / sh.area_samples


def composite_task(*, scene_path: str, scene_hash: str, camera: str | None, element_size: float,
                   store_url: str, frame: int, width: int, height: int, spp: int, seed: int,
                   max_depth: int, area_samples: int, adaptation: float, tonemap: dict,
                   out_dir: str, metadata: dict) -> dict:
    """Dask task: render one frame, tone-map it and write its EXR and PNG (atomically).

    Plain arguments in (``adaptation`` is the coordinator's smoothed value for this frame), a
    small dict of timings and ray counts out.
    """
    import time

    from pipeline.images import frame_paths, write_exr, write_png
    from pipeline.store.illumination import IlluminationMaps
    from pipeline.tonemap import ToneMapping
    from pipeline.tonemap import tonemap as tone

    from .scene_cache import load_elements, load_scene

    t0 = time.perf_counter()
    scene = load_scene(scene_path, scene_hash, camera)
    elements = load_elements(scene_path, scene_hash, element_size)
    state = scene.pose_frame(frame)
    irradiance = IlluminationMaps.open(store_url).read(frame - 1, "indirect")
    t1 = time.perf_counter()
    img = render_frame(state, elements, irradiance, width=width, height=height, spp=spp, seed=seed,
                       frame=frame, max_depth=max_depth, area_samples=area_samples)
    t2 = time.perf_counter()
    exr, png = frame_paths(out_dir, frame)
    write_exr(exr, img.beauty, img.alpha, {"direct": img.direct, "indirect": img.indirect,
                                           "albedo": img.albedo}, {**metadata, "frame": frame})
    write_png(png, tone(img.beauty, adaptation, ToneMapping(**tonemap)))
    t3 = time.perf_counter()
    return {"frame": frame, "rays": img.rays, "load_s": t1 - t0, "render_s": t2 - t1,
            "write_s": t3 - t2}
