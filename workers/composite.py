"""Final frames (§3, §6): ray-traced direct and specular light per pixel, indirect from the map.

For every pixel, ``spp`` jittered camera rays. At each hit:

* an emitter seen from its front face shows its emitted radiance (times its emissive texture);
* a **diffuse** surface gets direct light from every light with shadow rays (point, spot and
  directional exactly; emissive triangles by ``area_samples`` samples chosen by power, i.e. area x
  radiance; a sky, pipeline/scene/sky.py, by ``area_samples`` cosine-weighted directions) and
  indirect radiance rho/pi x E, E interpolated inside the hit element from its three
  vertex irradiances (the illumination map, workers/reconstruct.py); the path ends there;
* Lambert cosines, reflections and lobes use the shading normal (vertex normals), sidedness and
  ray offsets the geometric one; the albedo is the hit's base colour (factor x texture x COLOR_0),
  per sample, so textures are resolved per pixel (pipeline/scene/shading.py);
* a ray that leaves the scene shows the sky's radiance, if there is a sky (coverage stays 0);
* a **mirror** reflects, a **glossy** surface samples its normalised Phong lobe (the photon tracer's
  lobe, pipeline/scene/materials.py) and gets exact highlights of punctual lights; both continue up
  to ``max_depth`` reflections. Area lights reach glossy surfaces through the lobe samples only.

Layers per pixel (linear, radiance units): ``direct`` (emission and direct light, through the
specular chain), ``indirect`` (the map term), beauty = direct + indirect, and ``albedo`` of the
first surface hit. Ray counts per kind: camera, shadow (punctual lights), area (area-light and sky
shadow rays), reflection. Scenes without specular materials cast no reflection rays, scenes without
emissive triangles no area rays.

Determinism: every random number is a hash of (seed, frame, pixel, sample, dimension)
(splitmix64, Steele et al., OOPSLA 2014), so pixels do not depend on chunking or workers.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kernels.camera import camera_rays_cl, mix64
from kernels.sampling import around
from kernels.surface import LookupCL
from pipeline.scene import ElementMesh, FrameState
from pipeline.scene.shading import SurfaceShading

from .raycast import RayCaster, caster_for

CHUNK_RAYS = 1 << 14  # camera samples per wavefront: a working set two workers keep in the shared L3
RAY_KINDS = ("camera", "shadow", "area", "reflection")
_KIND = {"diffuse": 0, "mirror": 1, "glossy": 2}
_DIMS_PER_DEPTH = 16  # random dimensions per reflection depth: lobe (2) + area samples (3 each)
_FAR = 1e30  # shadow-ray length towards a directional light or the sky
_SKY_DIMS, _SKY_DIMS_PER_DEPTH = 1 << 20, 512  # random dimensions of sky samples (2 each, up to 256)


# --- counter-based random numbers -------------------------------------------------------------
_M64 = (1 << 64) - 1


def frame_key(seed: int, frame: int) -> int:
    """64-bit key of (seed, frame) for :func:`uniform`."""
    k = mix64(np.array([(seed * 0x9E3779B97F4A7C15 + 0x632BE59BD9B4E019) & _M64], np.uint64))
    return int(mix64(k ^ np.uint64(frame & _M64))[0])


def _hash(key: int, counter: np.ndarray, dim: int) -> np.ndarray:
    x = mix64(counter.astype(np.uint64) ^ np.uint64(key))
    return mix64(x + np.uint64((dim * 0x9E3779B97F4A7C15) & _M64))


def uniform(key: int, counter: np.ndarray, dim: int) -> np.ndarray:
    """float64 in [0, 1) for each counter (pixel x spp + sample) and a dimension number."""
    return (_hash(key, counter, dim) >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))


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
    """Per-frame tables the wavefront reads, per source triangle (one gather per hit): kind,
    albedo, emission, normal; the lights, the emitters' sampling table and the map."""

    def __init__(self, state: FrameState, elements: ElementMesh | None, irradiance, caster: RayCaster,
                 area_samples: int):
        mats = state.materials
        tri_mat = state.triangle_material.astype(np.int64)
        self.kind = np.array([_KIND[m.kind] for m in mats], np.int8)[tri_mat]
        self.albedo = np.array([m.albedo for m in mats], np.float32)[tri_mat]
        self.exponent = np.array([m.phong_exponent for m in mats], np.float32)[tri_mat]
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
        centre, radius = _bounding_spheres(corners)
        self.reach = [_light_reach(light, centre, radius) for light in state.lights]
        self.elements = elements
        self.element_irradiance = None  # (E, 3, 3) float32 [E0, E1 - E0, E2 - E0]: one gather a hit
        if irradiance is not None:
            e = np.asarray(irradiance, np.float64)[elements.element_vertices]
            self.element_irradiance = np.stack([e[:, 0], e[:, 1] - e[:, 0], e[:, 2] - e[:, 0]],
                                               axis=1).astype(np.float32)
        # Element and map irradiance of every hit, on PoCL (kernels/surface.cl)
        self.lookup = (LookupCL(elements.triangle_n, elements.triangle_offset[:-1], self.element_irradiance)
                       if elements is not None else None)
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


def render_frame(state: FrameState, elements: ElementMesh | None, irradiance, *, width: int,
                 height: int, spp: int, seed: int, frame: int, max_depth: int = 4,
                 area_samples: int = 2, caster: RayCaster | None = None,
                 chunk_rays: int = CHUNK_RAYS) -> FrameImage:
    """Render one frame; ``irradiance`` (V, 3) is the indirect map (None: no indirect light).

    ``chunk_rays`` camera samples are traced together (memory bound); pixels do not depend on it."""
    caster = caster or caster_for(state)
    sh = _Shading(state, elements, irradiance, caster, area_samples)
    key = frame_key(seed, frame)
    n_pixels = width * height
    layers = np.zeros((3, n_pixels, 3), np.float32)  # direct, indirect, albedo: contiguous planes
    alpha = np.zeros(n_pixels, np.float32)
    rays = dict.fromkeys(RAY_KINDS, 0)
    chunk_pixels = max(1, chunk_rays // spp)
    samples = None if spp == 1 else np.empty((3, chunk_pixels * spp, 3), np.float32)
    for lo in range(0, n_pixels, chunk_pixels):
        hi = min(n_pixels, lo + chunk_pixels)
        counter = np.arange(lo * spp, hi * spp, dtype=np.int64)
        if spp == 1:  # samples are pixels: trace straight into the layers
            alpha[lo:hi] = _trace_samples(state, sh, key, counter, spp, width, height, max_depth,
                                          rays, layers[:, lo:hi])
        else:  # mean over each pixel's samples (consecutive counters), in a fixed order
            out = samples[:, :len(counter)]
            out.fill(0)
            cover = _trace_samples(state, sh, key, counter, spp, width, height, max_depth, rays, out)
            layers[:, lo:hi] = out.reshape(3, hi - lo, spp, 3).mean(axis=2)
            alpha[lo:hi] = cover.reshape(hi - lo, spp).mean(axis=1)
    shape = (height, width, 3)
    direct, indirect, albedo = (layers[i].reshape(shape) for i in range(3))
    return FrameImage(direct + indirect, direct, indirect, albedo, alpha.reshape(shape[:2]), rays)


class _Hits:
    """One depth's ray hits. Points and normals are computed only for the rows a step asks for
    (None: all rows, cached), so hits no light reaches cost no geometry."""

    def __init__(self, sh: _Shading, tri, u, v, origins, dirs, t):
        self.tri, self.origins, self.dirs = tri, origins, dirs
        self.u, self.v = u, v
        self._surface = sh.surface
        self.cell, self.indirect = tri, None  # light-culling cell of every hit, map irradiance there
        if sh.lookup is not None:
            self.cell, self.indirect = sh.lookup(tri, u, v)
        self.t = t.astype(np.float32)
        self.u, self.v = u.astype(np.float32), v.astype(np.float32)
        self._normals, self._corners = sh.normals, sh.corners
        self._cache = {}

    def _full(self, name, make):
        if name not in self._cache:
            self._cache[name] = make(None)
        return self._cache[name]

    def points(self, rows=None) -> np.ndarray:
        """Hit points from the triangle's corners and Embree's barycentrics, not origin + t dir:
        their error follows the hit triangle's own scale, which the ray offsets assume
        (workers/raycast.py), however far the ray came."""
        if rows is None:
            return self._full("points", lambda _: self._interpolate(self.tri, self.u, self.v))
        return self._interpolate(np.take(self.tri, rows), np.take(self.u, rows), np.take(self.v, rows))

    def _interpolate(self, tri, u, v) -> np.ndarray:
        c = np.take(self._corners, tri, axis=0)
        return c[:, 0] + u[:, None] * (c[:, 1] - c[:, 0]) + v[:, None] * (c[:, 2] - c[:, 0])

    def normal(self, rows=None) -> np.ndarray:
        return np.take(self._normals, self.tri if rows is None else self.tri[rows], axis=0)

    def cos_in(self, rows=None) -> np.ndarray:
        """normal . ray direction (negative on the front face)."""
        if rows is None:
            return self._full("cos_in", lambda _: np.einsum("ij,ij->i", self.normal(), self.dirs))
        return np.einsum("ij,ij->i", self.normal(rows), np.take(self.dirs, rows, axis=0))

    def facing(self, rows=None) -> np.ndarray:
        """Unit normals turned towards the viewer (surfaces reflect on both faces)."""
        if rows is None:
            return self._full("facing", lambda _: self._facing(self.normal(), self.cos_in()))
        return self._facing(self.normal(rows), self.cos_in(rows))

    def shading(self, rows=None) -> np.ndarray:
        """Shading normals turned towards the viewer, in the hemisphere :meth:`facing` gives."""
        if not self._surface.smooth:
            return self.facing(rows)
        if rows is None:
            return self._full("shading", lambda _: self._shading(None))
        return self._shading(rows)

    def _shading(self, rows):
        tri, u, v = (self.tri, self.u, self.v) if rows is None else (self.tri[rows], self.u[rows], self.v[rows])
        n = self._surface.normal(tri, u, v).astype(np.float32)
        return n * np.where(self.cos_in(rows) < 0, np.float32(1), np.float32(-1))[:, None]

    def reflect(self, rows) -> np.ndarray:
        """Mirror directions of the rays ``rows`` about their shading normals."""
        n = self.shading(rows)
        d = np.take(self.dirs, rows, axis=0)
        return d - 2.0 * np.einsum("ij,ij->i", d, n)[:, None] * n

    @staticmethod
    def _facing(normal, cos_in):
        return normal * np.where(cos_in < 0, np.float32(1), np.float32(-1))[:, None]


def _trace_samples(state, sh: _Shading, key, counter, spp, width, height, max_depth, rays, out):
    """Add direct, indirect and albedo of the camera samples ``counter`` into ``out`` (3, n, 3),
    zero on entry; returns their coverage (n,)."""
    n = len(counter)
    cover = np.zeros(n, np.float32)
    cam = state.camera  # jittered camera rays (random dimensions 0 and 1), kernels/camera.cl
    dirs = camera_rays_cl(key, int(counter[0]), n, spp, width, height, cam.definition.yfov, cam.to_world[:3, :3])
    origins = np.broadcast_to(cam.position.astype(np.float32), dirs.shape)
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
        hits = _Hits(sh, tri, u, v, origins, dirs, t)
        kind = sh.kind[tri]
        if sh.surface.varies:  # textures or vertex colours: the base colour at every hit
            rho = sh.surface.base_color(tri, u, v).astype(np.float32)
        else:
            rho = np.take(sh.albedo, tri, axis=0)  # np.take: rows of a table, much faster than fancy indexing
        # This depth's layers: ``out`` itself while rays and samples correspond one to one,
        # else scattered into it once
        direct_out = path is None and throughput is None
        acc = out if direct_out else np.zeros((3, len(tri), 3), np.float32)
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
            e_direct = _punctual(sh, hits, None, None, rays, active)
            if sh.area_samples:
                c = counter if path is None else counter[path]
                e_direct += _area(sh, key, c, depth, hits, rays, active)
            if sh.sky_samples:
                c = counter if path is None else counter[path]
                e_direct += _sky(sh, key, c, depth, hits, rays, active)
            scale = (rho if active is None else rho * diffuse[:, None]) * np.float32(1.0 / np.pi)
            acc[0] += scale * e_direct
            if sh.element_irradiance is not None:
                acc[1] += scale * _interpolate(sh, hits)
            if active is None:
                if not direct_out:
                    _put_layers(out, path, acc if throughput is None else acc * throughput[None])
                break

        # Glossy: exact highlights of punctual lights
        glossy = np.flatnonzero(kind == 2)
        if len(glossy):
            mirror_g = hits.reflect(glossy)
            lobe = (mirror_g, sh.exponent[tri[glossy]])
            acc[0, glossy] += rho[glossy] * _punctual(sh, hits, glossy, lobe, rays, None)

        if not direct_out:
            _put_layers(out, path, acc if throughput is None else acc * throughput[None])

        # Mirror and glossy reflection continue the path
        spec = np.flatnonzero(kind != 0)
        if depth == max_depth or not len(spec):
            break
        refl = hits.reflect(spec)
        weight = rho[spec]
        g = np.flatnonzero(kind[spec] == 2)
        if len(g):
            e = sh.exponent[tri[spec[g]]].astype(np.float64)
            c = counter[spec[g] if path is None else path[spec[g]]]
            base = 2 + depth * _DIMS_PER_DEPTH
            cos_a = uniform(key, c, base) ** (1.0 / (e + 1.0))  # pdf (e+1)/(2 pi) cos^e
            lobe_dir = around(refl[g].astype(np.float64), cos_a, 2.0 * np.pi * uniform(key, c, base + 1))
            cos_o = np.einsum("ij,ij->i", lobe_dir, hits.shading(spec[g]))
            # normalised Phong BRDF rho (e+2)/(2 pi) cos^e times cos_o over the pdf
            weight[g] *= (np.maximum(cos_o, 0.0) * (e + 2.0) / (e + 1.0))[:, None]
            refl[g] = lobe_dir
        # leaving below the geometric surface (shading normals) ends the path, as in the tracer
        keep = (weight.max(axis=1) > 0) & (np.einsum("ij,ij->i", refl, hits.facing(spec)) > 0)
        spec, refl, weight = spec[keep], refl[keep], weight[keep]
        throughput = weight if throughput is None else throughput[spec] * weight
        origins = sh.caster.offset_origins(hits.points(spec), tri[spec], refl).astype(np.float32)
        dirs, path = refl, (spec if path is None else path[spec])
    return cover


def _put_layers(target: np.ndarray, idx, value) -> None:
    """target[:, idx] += value for layers (3, n, 3); idx None means all samples in order."""
    if idx is None:
        target += value
    else:
        target[:, idx] += value


def _put(target: np.ndarray, idx, value, accumulate: bool = False) -> None:
    """target[idx] = value (or +=); idx None means all rows in order."""
    if idx is None:
        if accumulate:
            target += value
        else:
            target[...] = value
    elif accumulate:
        target[idx] += value
    else:
        target[idx] = value


def _interpolate(sh: _Shading, hits: _Hits) -> np.ndarray:
    """Irradiance inside the hit element: barycentric blend of its three vertex values (computed
    with the element lookup, kernels/surface.py)."""
    return hits.indirect


def _bounding_spheres(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centres and radii (slightly enlarged) of triangles given as (n, 3, 3) corners."""
    centre = corners.mean(axis=1)
    radius = np.sqrt(((corners - centre[:, None]) ** 2).sum(axis=2)).max(axis=1) * 1.001 + 1e-9
    return centre, radius


def _light_reach(light, centre: np.ndarray, radius: np.ndarray) -> np.ndarray | None:
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


def _punctual(sh: _Shading, hits: _Hits, rows, lobe, rays, active) -> np.ndarray:
    """Irradiance (lobe None) or glossy radiance over rho (lobe = (mirror dirs, exponents)) at
    the hits ``rows`` (None: all) from every point, spot and directional light, with shadow rays.
    Hits a light cannot reach (its cone or range misses their triangle, back side, outside the
    cone) and hits not ``active`` (None: all are) are culled before any square root or ray."""
    cell = hits.cell if rows is None else hits.cell[rows]
    total = np.zeros((len(cell), 3), np.float32)
    for light, reach in zip(sh.lights, sh.reach):
        mask = active if reach is None else (reach[cell] if active is None else reach[cell] & active)
        idx = None if mask is None else np.flatnonzero(mask)  # rows of ``total`` to consider
        if idx is not None and not len(idx):
            continue
        where = idx if rows is None else (rows if idx is None else rows[idx])  # rows of ``hits``
        p, facing, shade = hits.points(where), hits.facing(where), hits.shading(where)
        if light.kind == "directional":
            to_light = (-light.direction).astype(np.float32)
            cos_s = shade @ to_light
            sel = np.flatnonzero(cos_s > 0)
            d = np.broadcast_to(to_light, (len(sel), 3))
            dist = np.full(len(sel), _FAR)
            cos_s = cos_s[sel]
            scale = np.ones(len(sel), np.float32)
        else:
            delta = light.position.astype(np.float32) - p
            ahead = np.einsum("ij,ij->i", shade, delta)  # cos x distance (shading normal)
            keep = ahead > 0
            if light.kind == "spot":  # inside the outer cone: proj > cos_outer x distance
                proj = delta @ -light.direction.astype(np.float32)
                dist2 = np.einsum("ij,ij->i", delta, delta)
                keep &= (proj > 0) & (proj * proj > np.cos(light.definition.outer_cone) ** 2 * dist2)
            sel = np.flatnonzero(keep)
            delta = delta[sel]
            dist = np.sqrt(np.einsum("ij,ij->i", delta, delta))
            d = delta / dist[:, None]
            cos_s = ahead[sel] / dist
            scale = 1.0 / (dist * dist)
            if light.definition.range is not None:
                scale = scale * light.range_window(dist)
            if light.kind == "spot":
                scale = scale * light.spot_falloff(proj[sel] / dist)
        out_rows = sel if idx is None else idx[sel]
        if lobe is not None:  # normalised Phong: (e+2)/(2 pi) cos^e(angle to the mirror direction)
            e = lobe[1][out_rows]
            cos_r = np.maximum(np.einsum("ij,ij->i", lobe[0][out_rows], d), 0.0)
            scale = scale * (e + 2.0) / (2.0 * np.pi) * cos_r ** e
        live = scale > 0
        if not live.all():
            sel, out_rows, d, dist, cos_s, scale = (a[live] for a in (sel, out_rows, d, dist, cos_s, scale))
        if not len(sel):
            continue
        d = np.ascontiguousarray(d, np.float32)
        tri = hits.tri if where is None else hits.tri[where]
        # geometric offset; a light below it is shadowed
        origin = p[sel] + facing[sel] * sh.offsets[tri[sel]][:, None]
        blocked = sh.caster.occluded(origin, d, dist * (1.0 - 1e-5))
        rays["shadow"] += len(sel)
        free = ~blocked
        total[out_rows[free]] += (scale[free] * cos_s[free]).astype(np.float32)[:, None] * \
            light.radiant.astype(np.float32)
    return total


def _area(sh: _Shading, key, counter, depth, hits: _Hits, rays, active) -> np.ndarray:
    """Irradiance from emissive triangles at every hit: ``area_samples`` samples each, triangle
    chosen by power, point uniform on it (pbrt-v4 SampleUniformTriangle); E = L cos cos' / (d^2 pdf)."""
    p, facing, shade, tri = hits.points(), hits.facing(), hits.shading(), hits.tri
    total = np.zeros((len(p), 3), np.float32)
    base = 2 + depth * _DIMS_PER_DEPTH + 2
    for s in range(sh.area_samples):
        u0, u1, u2 = (uniform(key, counter, base + 3 * s + j) for j in range(3))
        pick = np.minimum(np.searchsorted(sh.area_cdf, u0, side="right"), len(sh.area_cdf) - 1)
        su = np.sqrt(u1)
        b1, b2 = (su * (1.0 - u2)).astype(np.float32), (su * u2).astype(np.float32)
        c = np.take(sh.area_corners, pick, axis=0)
        y = c[:, 0] + b1[:, None] * (c[:, 1] - c[:, 0]) + b2[:, None] * (c[:, 2] - c[:, 0])
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


def _sky(sh: _Shading, key, counter, depth, hits: _Hits, rays, active) -> np.ndarray:
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
    base = _SKY_DIMS + depth * _SKY_DIMS_PER_DEPTH
    for s in range(sh.sky_samples):
        u1, u2 = uniform(key, c, base + 2 * s), uniform(key, c, base + 2 * s + 1)
        d = np.ascontiguousarray(around(lobe, np.sqrt(u1), 2.0 * np.pi * u2), np.float32)
        free = ~sh.caster.occluded(origin, d, np.full(len(rows), _FAR, np.float32))
        free &= np.einsum("ij,ij->i", d, facing) > 0
        rays["area"] += len(rows)
        total[rows[free]] += sh.sky.radiance(d[free])
    return total * np.float32(np.pi / sh.sky_samples)


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
    irradiance = IlluminationMaps.open_shared(store_url).read(frame - 1, "indirect")
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
