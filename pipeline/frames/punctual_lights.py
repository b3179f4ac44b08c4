"""Point, spot and directional lights in the compositor: exact direct light with one shadow ray per
light and hit (irradiance of diffuse hits, highlights of glossy ones), and the light culling that
skips hits a light's cone or range cannot reach.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:

    from .camera_hits import CameraHits
    from .shading_tables import ShadingTables

FAR = 1e30  # shadow-ray length towards a directional light or the sky


def punctual_light(sh: ShadingTables, hits: CameraHits, rows: np.ndarray | None,
                   lobe: tuple[np.ndarray, np.ndarray] | None, rays: dict[str, int],
                   active: np.ndarray | None) -> np.ndarray:
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
            dist = np.full(len(sel), FAR)
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
