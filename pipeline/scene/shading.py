"""The surface at a ray hit: shading normal and base colour, the same for photons and pixels.

* **Shading normal**: the primitive's ``NORMAL`` vertex normals, carried to world space by the
  inverse transpose of the node's matrix and renormalised (:func:`world_corner_normals`, per pose),
  interpolated with the hit's barycentrics and renormalised again. It is turned into the geometric
  normal's hemisphere, so which side a surface is seen from (sidedness) and where secondary rays
  start (offsets, pipeline/photons/raycast.py) still come from the geometric normal; primitives without
  ``NORMAL`` are flat shaded, as glTF 2.0 §3.7.2.1 asks. Lambert cosines, mirror and lobe directions
  use the shading normal (kernels/scatter.py, pipeline/frames/camera_paths.py).
* **Normal maps**: a material's ``normalTexture`` bends that normal by the texel's tangent-space
  normal (:meth:`SurfaceShading._bent`), in the frame of the file's ``TANGENT`` (posed, per corner:
  :func:`world_corner_tangents`, pipeline/scene/animation.py ``pose_tangents``), else of the
  triangle's dp/du. Photons and pixels bounce and shade about the bent normal.
* **Base colour**: ``baseColorFactor`` RGB x the ``baseColorTexture`` (pipeline/scene/textures.py) at
  the hit's interpolated ``TEXCOORD_n`` x the interpolated ``COLOR_0`` (glTF 2.0 §3.9.2). The photon
  tracer takes its Russian-roulette albedo from here, so colour bleeding follows the texture; the
  photon records do not change (pipeline/store/records.py).
* **Kind**: a material's kind (diffuse, mirror, glossy) and Phong exponent, or, where it has a
  ``metallicRoughnessTexture``, those of the texel at the hit (:meth:`SurfaceShading.kinds`; the
  classification is pipeline/scene/materials.py's): a photon bounces and a pixel shades by the texel.
* **Emission**: ``emissiveFactor x strength x emissiveTexture`` (glTF 2.0 §3.9.5; vertex colours do
  not apply): seen emitters and area-light samples in the compositor, photon weights at emission.

Embree's hit barycentrics (u, v) weight a triangle's corners 1 and 2 (pipeline/photons/raycast.py).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .animation import transform_tangents
from .materials import KINDS, kind_codes, phong_exponents
from .textures import Texture, sample

if TYPE_CHECKING:
    from collections.abc import Sequence

    import numpy.typing as npt

    from .materials import Material
    from .nodes import MeshInstance

MEAN_POINTS = 256  # points per emissive triangle for its mean textured radiance


@dataclass(frozen=True, eq=False)
class CornerAttributes:
    """Pose-independent per-corner data of every source triangle (global triangle order)."""

    texcoords: dict[int, np.ndarray]  # set -> (F, 3, 2) float32; zeros where an instance lacks the set
    color: np.ndarray | None  # (F, 3, 3) float32 linear RGB; ones where an instance has no COLOR_0
    alpha: np.ndarray | None = None  # (F, 3) float32 COLOR_0's alpha; ones where an instance has none

    @property
    def empty(self) -> bool:
        return not self.texcoords and self.color is None


def corner_attributes(instances: Sequence[MeshInstance]) -> CornerAttributes | None:
    """TEXCOORD sets and COLOR_0 of every triangle corner, None when no instance has any."""
    attrs = [inst.attributes for inst in instances]
    sets = sorted({s for a in attrs if a is not None for s in a.texcoords})
    has_color = any(a is not None and a.color is not None for a in attrs)
    if not sets and not has_color:
        return None
    texcoords = {}
    for s in sets:
        texcoords[s] = np.concatenate([
            a.texcoords[s][inst.faces] if a is not None and s in a.texcoords
            else np.zeros((len(inst.faces), 3, 2), np.float32)
            for inst, a in zip(instances, attrs)])
    color = None
    if has_color:
        color = np.concatenate([
            a.color[inst.faces] if a is not None and a.color is not None
            else np.ones((len(inst.faces), 3, 3), np.float32)
            for inst, a in zip(instances, attrs)])
    alpha = None
    if any(a is not None and a.alpha is not None for a in attrs):
        alpha = np.concatenate([a.alpha[inst.faces] if a is not None and a.alpha is not None
                                else np.ones((len(inst.faces), 3), np.float32) for inst, a in zip(instances, attrs)])
    return CornerAttributes(texcoords, color, alpha)


def world_corner_tangents(instances: Sequence[MeshInstance], matrices: np.ndarray) -> np.ndarray | None:
    """(F, 3, 4) float32 world-space TANGENTs at every triangle corner (unit xyz, w the handedness
    with the node's mirroring), zero where an instance has none; None when no instance has any."""
    return _world_corners(instances, matrices, "tangents", 4, transform_tangents)


def world_corner_normals(instances: Sequence[MeshInstance], matrices: np.ndarray) -> np.ndarray | None:
    """(F, 3, 3) float32 world-space unit vertex normals at every triangle corner, zero where an
    instance has no NORMAL (flat there); None when no instance has normals. A normal transforms by
    the inverse transpose of the linear part of its node's matrix."""
    return _world_corners(instances, matrices, "normals", 3, _carry_normals)


def _carry_normals(normals: np.ndarray, linear: np.ndarray) -> np.ndarray | None:
    try:
        inverse_t = np.linalg.inv(linear).T
    except np.linalg.LinAlgError:  # a node scaled to nothing: its triangles have no area
        return None
    n = normals @ inverse_t.T
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 1e-12)


def _world_corners(instances: Sequence[MeshInstance], matrices: np.ndarray, attribute: str, width: int,
                   carry) -> np.ndarray | None:
    """(F, 3, width) float32 per-corner world values of the vertex ``attribute``, each instance's
    carried by ``carry(values, linear part of its matrix)`` (None: zeros), zero where an instance
    lacks it; None where no instance has it."""
    if not any(inst.attributes is not None and getattr(inst.attributes, attribute) is not None
               for inst in instances):
        return None
    parts = []
    for inst, m in zip(instances, matrices):
        values = None if inst.attributes is None else getattr(inst.attributes, attribute)
        world = None if values is None else carry(values, m[:3, :3])
        parts.append(np.zeros((len(inst.faces), 3, width), np.float32) if world is None
                     else world[inst.faces].astype(np.float32))
    return np.concatenate(parts)


class SurfaceShading:
    """Shading normals and base colours at hits of one frame state (see the module docstring)."""

    def __init__(self, state, geometric_normals: np.ndarray):
        self.geometric = np.asarray(geometric_normals, np.float64)
        self.corner_normals = getattr(state, "corner_normals", None)
        self.corner_tangents = getattr(state, "corner_tangents", None)  # the file's TANGENTs, posed
        # triangles with vertex normals: the only ones whose hits need interpolating
        self.smooth_triangle = (None if self.corner_normals is None
                                else np.any(self.corner_normals != 0, axis=(1, 2)))
        corners = getattr(state, "corners", None)
        self.texcoords = corners.texcoords if corners is not None else {}
        self.color = corners.color if corners is not None else None
        self.tri_mat = state.triangle_material.astype(np.int64)
        mats = state.materials
        self.factor = np.array([m.albedo for m in mats], np.float64)
        self.textures = {j: m.base_color_texture for j, m in enumerate(mats)
                         if getattr(m, "base_color_texture", None) is not None}
        used = set(np.unique(self.tri_mat).tolist()) if len(self.tri_mat) else set()
        self.textures = {j: t for j, t in self.textures.items() if j in used}
        self.emission_factor = np.array([m.emission for m in mats], np.float64)
        self.emissive_textures = {j: m.emissive_texture for j, m in enumerate(mats)
                                  if j in used and m.is_emissive and getattr(m, "emissive_texture", None) is not None}
        self.normal_maps = {j: (m.normal_texture, m.normal_scale) for j, m in enumerate(mats)
                            if j in used and getattr(m, "normal_texture", None) is not None}
        self.kind = np.array([KINDS.index(m.kind) for m in mats], np.int8)
        self.exponent = np.array([m.phong_exponent for m in mats], np.float64)
        self.metallic_roughness = {j: (m.metallic_roughness_texture, m.metallic, m.roughness)
                                   for j, m in enumerate(mats)
                                   if j in used and getattr(m, "metallic_roughness_texture", None) is not None
                                   and m.kind != "dielectric"}  # glass stays glass
        self.vertices, self.faces = getattr(state, "vertices", None), getattr(state, "faces", None)
        # Beer's law inside solid glass: extinction per unit length (3,) of each attenuating volume
        self.extinction = {j: -np.log(np.maximum(m.attenuation_color, 1e-12)) / m.attenuation_distance
                           for j, m in enumerate(mats) if j in used and m.kind == "dielectric"
                           and np.isfinite(m.attenuation_distance) and min(m.attenuation_color) < 1}

    @property
    def smooth(self) -> bool:
        """True when the shading normal differs from the geometric one somewhere: some triangle has
        vertex normals or a normal map."""
        return self.corner_normals is not None or bool(self.normal_maps)

    @property
    def varies(self) -> bool:
        """True when the base colour varies inside a triangle (textures or vertex colours)."""
        return bool(self.textures) or self.color is not None

    def normal(self, tri: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(n, 3) float64 unit shading normals at the hits, in the geometric normal's hemisphere.
        ``tri`` may hold -1 (a miss): those rows get triangle 0's normal and mean nothing."""
        t = np.maximum(np.asarray(tri), 0)
        geo = np.take(self.geometric, t, axis=0)
        if not self.smooth:
            return geo
        n = geo.copy()
        rows = np.flatnonzero(self.smooth_triangle[t]) if self.corner_normals is not None else ()
        if len(rows):
            c = np.take(self.corner_normals, t[rows], axis=0).astype(np.float64)
            smooth = interpolate(c, np.take(u, rows), np.take(v, rows))
            length = np.sqrt(np.einsum("ij,ij->i", smooth, smooth))
            ok = length > 1e-6
            n[rows] = np.where(ok[:, None], smooth / np.where(ok, length, 1.0)[:, None], geo[rows])
        if self.normal_maps:
            n = self._bent(n, t, np.asarray(u, np.float64), np.asarray(v, np.float64))
        return n * np.where(np.einsum("ij,ij->i", n, geo) < 0, -1.0, 1.0)[:, None]

    def _bent(self, n: np.ndarray, t: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``n`` bent by each normal-mapped material's map: the texel's tangent-space normal
        ``(2 c - 1) x (scale, scale, 1)`` in the frame of the triangle's dp/du (its texture
        coordinates as the texture transform maps them), made orthogonal to ``n``, the bitangent
        ``n x t`` towards decreasing v, as glTF's +Y-up maps want (pbrt-v4's NormalMap and the Khronos
        sample viewer build the same frame where a file gives no TANGENT). Where the file gives
        TANGENTs, their interpolation is the tangent instead, and ``w (n x t)`` the bitangent
        (glTF 2.0 §3.7.2.1: the frame the map was baked in). Triangles with neither keep ``n``."""
        m = self.tri_mat[t]
        for j, (tex, scale) in self.normal_maps.items():
            rows = np.flatnonzero(m == j)
            corners = self.texcoords.get(tex.texcoord)
            if not len(rows) or corners is None or self.vertices is None:
                continue
            tri = t[rows]
            raw = np.take(corners, tri, axis=0).astype(np.float64)
            uv = raw @ tex.transform[:, :2].T + tex.transform[:, 2]
            p = self.vertices[self.faces[tri]].astype(np.float64)
            dpdu, dpdv, ok = uv_derivatives(p, uv)
            nn = n[rows]
            tangent = dpdu - nn * np.einsum("ij,ij->i", nn, dpdu)[:, None]
            length = np.linalg.norm(tangent, axis=1)
            ok &= length > 1e-12
            tangent = tangent / np.where(ok, length, 1.0)[:, None]
            across = np.cross(nn, tangent)
            side = np.sign(np.einsum("ij,ij->i", across, -dpdv))
            bitangent = across * np.where(side == 0, 1.0, side)[:, None]
            if self.corner_tangents is not None:
                self._file_frame(tri, u[rows], v[rows], nn, (tangent, bitangent, ok))
            texel = sample(tex, interpolate(raw, u[rows], v[rows]))
            local = (2.0 * texel - 1.0) * np.array([scale, scale, 1.0])
            bent = local[:, :1] * tangent + local[:, 1:2] * bitangent + local[:, 2:] * nn
            length = np.linalg.norm(bent, axis=1)
            ok &= length > 1e-12
            n[rows] = np.where(ok[:, None], bent / np.where(ok, length, 1.0)[:, None], nn)
        return n

    def _file_frame(self, tri: np.ndarray, u: np.ndarray, v: np.ndarray, nn: np.ndarray, frame: tuple) -> None:
        """Overwrite ``frame`` (tangent, bitangent, ok) in place where the triangles ``tri`` have the
        file's TANGENT at all three corners: the interpolated tangent made orthogonal to ``nn``, and
        ``w (nn x t)``."""
        tangent, bitangent, ok = frame
        corners = np.take(self.corner_tangents, tri, axis=0).astype(np.float64)
        rows = np.flatnonzero(np.all(np.any(corners[:, :, :3] != 0, axis=2), axis=1))
        if not len(rows):
            return
        t = interpolate(corners[rows, :, :3], u[rows], v[rows])
        t -= nn[rows] * np.einsum("ij,ij->i", nn[rows], t)[:, None]
        length = np.linalg.norm(t, axis=1)
        rows, t, length = rows[length > 1e-12], t[length > 1e-12], length[length > 1e-12]
        tangent[rows] = t / length[:, None]
        w = np.where(corners[rows, :, 3].sum(axis=1) < 0, -1.0, 1.0)
        bitangent[rows] = np.cross(nn[rows], tangent[rows]) * w[:, None]
        ok[rows] = True

    def base_color(self, tri: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(n, 3) float64 base colour at the hits (factor x texture x COLOR_0); -1 rows: triangle 0."""
        t = np.maximum(np.asarray(tri), 0)
        m = self.tri_mat[t] if len(self.tri_mat) else np.zeros(len(t), np.int64)
        rho = np.take(self.factor, m, axis=0)
        if self.color is not None:
            rho = rho * interpolate(np.take(self.color, t, axis=0).astype(np.float64), u, v)
        return self._textured(self.textures, rho, t, m, u, v)

    @property
    def kind_varies(self) -> bool:
        """True when some material's kind or lobe varies inside its triangles (metallic-roughness textures)."""
        return bool(self.metallic_roughness)

    def kinds(self, tri: np.ndarray, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(kind codes int8, Phong exponents float64) at the hits: the material's, or for a material
        with a metallic-roughness texture, its factors x the texel's B (metallic) and G (roughness)."""
        t = np.maximum(np.asarray(tri), 0)
        m = self.tri_mat[t] if len(self.tri_mat) else np.zeros(len(t), np.int64)
        kind, exponent = np.take(self.kind, m), np.take(self.exponent, m)
        for j, (tex, metallic, roughness) in self.metallic_roughness.items():
            rows = np.flatnonzero(m == j)
            if not len(rows):
                continue
            texel = self._texel(tex, t[rows], np.take(u, rows), np.take(v, rows))
            r = np.clip(roughness * texel[:, 1], 0.0, 1.0)
            kind[rows] = kind_codes(metallic * texel[:, 2], r)
            exponent[rows] = phong_exponents(r)
        return kind, exponent

    def volume_transmittance(self, tri: np.ndarray, dirs: np.ndarray, dist: np.ndarray) -> np.ndarray | None:
        """(n, 3) float64 share of light kept along rays that travelled ``dist`` to hits ``tri`` (-1: a
        miss) inside an attenuating glass volume, known by meeting its surface from the back
        (a closed volume's normals point out); 1 elsewhere. None where no volume attenuates."""
        if not self.extinction:
            return None
        t = np.maximum(np.asarray(tri), 0)
        m = self.tri_mat[t]
        out = np.ones((len(t), 3))
        leaving = (np.asarray(tri) >= 0) & (np.einsum("ij,ij->i", np.take(self.geometric, t, axis=0), dirs) > 0)
        for j, sigma in self.extinction.items():
            rows = np.flatnonzero(leaving & (m == j))
            out[rows] = np.exp(-np.asarray(dist, np.float64)[rows, None] * sigma[None, :])
        return out

    @property
    def emission_varies(self) -> bool:
        """True when some emitter's radiance varies inside its triangles (emissive textures)."""
        return bool(self.emissive_textures)

    def emission(self, tri: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(n, 3) float64 emitted radiance at the hits: emissive factor x strength x texture."""
        t = np.maximum(np.asarray(tri), 0)
        m = self.tri_mat[t] if len(self.tri_mat) else np.zeros(len(t), np.int64)
        return self._textured(self.emissive_textures, np.take(self.emission_factor, m, axis=0), t, m, u, v)

    def mean_emission(self, tri: np.ndarray) -> np.ndarray:
        """(n, 3) emitted radiance averaged over each triangle: exact without an emissive texture,
        else the mean of :data:`MEAN_POINTS` stratified, area-uniform points (what emitters are
        chosen by; photon weights then carry L(x) / this mean, pipeline/photons/emission.py)."""
        tri = np.asarray(tri, np.int64)
        out = np.take(self.emission_factor, self.tri_mat[tri], axis=0) if len(tri) else np.zeros((0, 3))
        if not self.emission_varies or not len(tri):
            return out
        k = int(round(np.sqrt(MEAN_POINTS)))
        g = (np.arange(k) + 0.5) / k
        su, w = np.sqrt(np.repeat(g, k)), np.tile(g, k)
        b1, b2 = su * (1.0 - w), su * w  # pbrt's uniform triangle mapping, cell centres
        textured = np.flatnonzero(np.isin(self.tri_mat[tri], list(self.emissive_textures)))
        rep = np.repeat(tri[textured], len(b1))
        values = self.emission(rep, np.tile(b1, len(textured)), np.tile(b2, len(textured)))
        out[textured] = values.reshape(len(textured), len(b1), 3).mean(axis=1)
        return out

    def _textured(self, textures: dict, value: np.ndarray, t, m, u, v) -> np.ndarray:
        """``value`` (n, 3) times each textured material's texture at its hits' texture coordinates."""
        for j, tex in textures.items():
            rows = np.flatnonzero(m == j)
            if len(rows):
                value[rows] *= self._texel(tex, t[rows], np.take(u, rows), np.take(v, rows))
        return value

    def _texel(self, tex, tri: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return texel_at(self.texcoords, tex, tri, u, v)


def mean_emission(material: Material) -> np.ndarray:
    """(3,) a material's emitted radiance averaged over its emissive texture."""
    emission = np.asarray(material.emission, np.float64)
    tex = getattr(material, "emissive_texture", None)
    return emission if tex is None else emission * tex.mean


def mean_base_color(material: Material) -> np.ndarray:
    """(3,) a material's base colour averaged over its texture (factor x texel mean): what a
    mesh-level estimate such as the adaptation luminance (pipeline/collection/estimators.py) can use."""
    factor = np.asarray(material.albedo, np.float64)
    tex = getattr(material, "base_color_texture", None)
    return factor if tex is None else factor * tex.mean


def uv_derivatives(p: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """dp/du, dp/dv (n, 3) of triangles with corners ``p`` (n, 3, 3) and texture coordinates ``uv``
    (n, 3, 2), and where they exist (the coordinates span an area); pbrt-v4, Triangle::
    InteractionFromIntersection."""
    duv02, duv12 = uv[:, 0] - uv[:, 2], uv[:, 1] - uv[:, 2]
    dp02, dp12 = p[:, 0] - p[:, 2], p[:, 1] - p[:, 2]
    det = duv02[:, 0] * duv12[:, 1] - duv02[:, 1] * duv12[:, 0]
    ok = np.abs(det) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)[:, None]
    dpdu = (duv12[:, 1:2] * dp02 - duv02[:, 1:2] * dp12) * inv
    dpdv = (duv02[:, 0:1] * dp12 - duv12[:, 0:1] * dp02) * inv
    return dpdu, dpdv, ok


def texel_at(texcoords: dict, tex: Texture, tri: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(n, 3) float64 texture ``tex`` at hits of triangles ``tri``, at their texture coordinates
    interpolated from the per-corner ``texcoords`` (CornerAttributes'; (0, 0) where the primitive
    has none): the one lookup of every texture slot, shading's and cut-outs' alike."""
    corners = texcoords.get(tex.texcoord)
    if corners is None:
        uv = np.zeros((len(tri), 2))
    else:
        uv = interpolate(np.take(corners, tri, axis=0).astype(np.float64), u, v)
    return sample(tex, uv)


def interpolate(corners: np.ndarray, u: npt.ArrayLike, v: npt.ArrayLike) -> np.ndarray:
    """Barycentric blend of (n, 3, k) corner values with Embree's (u, v) (corners 1 and 2), float64:
    shading normals, vertex colours and texture coordinates (here), the photon tracer's and the
    compositor's alike. Positions use :func:`triangle_points`."""
    u = np.asarray(u, np.float64)[:, None]
    v = np.asarray(v, np.float64)[:, None]
    return (1.0 - u - v) * corners[:, 0] + u * corners[:, 1] + v * corners[:, 2]


def triangle_points(corners: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Points of (n, 3, 3) triangles at barycentrics (u, v) (corners 1 and 2), in the corners' dtype
    (float32 in the compositor), as corner 0 plus the two edges: the compositor's hit points and its
    area-light samples. Not :func:`interpolate`'s float64 weighted sum: the rounding differs, and the
    ray offsets (pipeline/photons/raycast.py) and the frames' bits are those of this form."""
    return corners[:, 0] + u[:, None] * (corners[:, 1] - corners[:, 0]) + v[:, None] * (corners[:, 2] - corners[:, 0])
