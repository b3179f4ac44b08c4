"""1e8 photons accumulated for one frame without drift (slow).

A point light between a mirror floor and a black diffuse ceiling tile: photons going up hit the
tile first (direct records), photons reflected by the mirror hit it second (indirect records,
summed by the OpenCL gather of pipeline/collection/maps.py); the tile's albedo 0 ends every path there.
One frame of 1e8 photons gives about 2.1e6 records. Bound: every map value is a sum of n records
in float64, added in a fixed order, whose relative error is at most (n - 1) u = 1.1e-8 for
n = 1e8 (u = 2^-53; Higham, *Accuracy and Stability of Numerical Algorithms*, §4.2), then rounded
once to the float32 of the store (6e-8): the stored maps must equal extended-precision (80-bit
long double) sums of the stored records within 1e-6. A float32 running sum would stall at 2^24
records. The totals also match the closed forms: flux I x Omega of the tile seen from the light,
and I x rho x Omega' seen from the light's mirror image, within 4 standard errors.
"""
from __future__ import annotations

import numpy as np
import pytest

from pipeline.config import FilterConfig, RenderConfig
from pipeline.frames.settings import RenderSettings
from pipeline.run.render import RenderRequest, render
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.builtin.gltf_builder import GltfBuilder
from pipeline.scene.builtin.shapes import look_at
from pipeline.store import PhotonStore
from pipeline.store.illumination import IlluminationMaps

N = 100_000_000
I, RHO, H, A = 5.0, 0.9, 1.0, 0.25  # noqa: E741 (intensity, mirror reflectance, tile height, half-side)


def _rect_solid_angle(a, h):
    """Solid angle of a 2a x 2a square centred h away from a point on its axis."""
    return 4 * np.arctan(a * a / (h * np.sqrt(2 * a * a + h * h)))


def _scene(path):
    b = GltfBuilder()
    mirror = b.add_material("mirror", (RHO, RHO, RHO), metallic=1.0, roughness=0.0)
    black = b.add_material("tile", (0.0, 0.0, 0.0))
    floor = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], float)
    b.add_node("mirror", b.add_mesh("mirror", floor, np.array([0, 2, 1, 0, 3, 2]), material=mirror))
    tile = np.array([[-A, 0, -A], [A, 0, -A], [A, 0, A], [-A, 0, A]], float) + [0, 2 * H, 0]
    b.add_node("tile", b.add_mesh("tile", tile, np.array([0, 1, 2, 0, 2, 3]), material=black))
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), I), translation=(0, H, 0))
    eye = (0.0, 0.5, 3.0)
    b.add_node("cam", camera=b.add_camera("cam", 0.8, 0.05), translation=eye, rotation=look_at(eye, (0, 1, 0)))
    b.set_scene_extras({"photonloom": {"element_size": 0.1}})
    return b.write(path)


def _long_double_map(records, select, elements, areas):
    """Vertex irradiance of the selected records, summed in 80-bit long double after sorting."""
    el = records.element[select].astype(np.int64)
    w1 = records.b1[select].astype(np.longdouble) / 65535
    w2 = records.b2[select].astype(np.longdouble) / 65535
    weights = np.stack([1 - w1 - w2, w1, w2])  # (3, n)
    e = records.energy[select].astype(np.longdouble)  # (n, 3)
    vertex = elements.element_vertices[el].T  # (3, n)
    idx = vertex.reshape(-1)
    order = np.argsort(idx, kind="stable")
    flux = (weights[:, :, None] * e[None]).reshape(-1, 3)[order]
    starts = np.flatnonzero(np.concatenate([[True], np.diff(idx[order]) != 0]))
    s = np.zeros((elements.n_vertices, 3), np.longdouble)
    s[idx[order][starts]] = np.add.reduceat(flux, starts, axis=0)
    out = np.zeros_like(s)
    ok = areas > 0
    out[ok] = s[ok] / (np.longdouble(records.photons_emitted) * areas[ok, None])
    return out


@pytest.mark.slow
def test_1e8_photons_accumulate_without_drift(tmp_path):
    path = _scene(tmp_path / "tile.glb")
    out = tmp_path / "out"
    render(RenderRequest(scene_path=path, frames="1", out_dir=out, n_photons=N, temporal="off",
                         config=RenderConfig(filter=FilterConfig(spatial_filter=False)),
                         settings=RenderSettings(width=16, height=12, spp=1), keep_records=True),
           scheduler="synchronous")
    scene = read_scene(path)
    elements = ElementMesh.build(scene)
    areas = elements.vertex_areas(scene.pose_frame(1)).astype(np.longdouble)
    records = PhotonStore.open(str(out / "photons.zarr")).read_frame(0)
    assert records.photons_emitted == N and len(records) > 1_500_000
    maps = IlluminationMaps.open(str(out / "photons.zarr"))
    tile = np.zeros(elements.n_vertices, bool)
    tile[elements.element_vertices[records.element]] = True
    for name, select in (("direct", records.direct), ("indirect", ~records.direct)):
        exact = _long_double_map(records, select, elements, areas)
        stored = maps.read(0, name).astype(np.longdouble)
        np.testing.assert_allclose(stored[tile].astype(float), exact[tile].astype(float), rtol=1e-6, atol=0)
        # closed forms for the total flux on the tile
        total = float((stored * areas[:, None]).sum(axis=0)[1]) * N
        count = int(np.count_nonzero(select))
        if name == "direct":
            expected = I * _rect_solid_angle(A, H)
        else:
            expected = I * RHO * _rect_solid_angle(A, 3 * H)
        photon_weight = 4 * np.pi * I * (RHO if name == "indirect" else 1.0)
        assert abs(total / N - expected) <= 4 * photon_weight * np.sqrt(count) / N, (name, total / N, expected)
