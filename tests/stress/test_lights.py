"""A 1e6:1 ratio between two lights (docs/04-photons.md §1).

The bright lights sit in one closed room, a lamp 1e6 times dimmer in a closed room of its own. By
power alone the dim room would get 0.2 of 200,000 photons a frame: no indirect light in most
frames, and now and then one photon of the bright lights' weight, 1e6 times its own light. Every
light gets a floor share of the photons (pipeline/photons/emission.py LIGHT_FLOOR), so the dim room's
indirect light equals that of the dim lamp alone, within noise, and the total flux is unbiased.
"""
from __future__ import annotations

import numpy as np
import pytest

from pipeline.config import PhotonConfig
from pipeline.frames.images import frame_paths, read_exr
from pipeline.frames.settings import RenderSettings
from pipeline.photons.tracing import PhotonRange, trace_batch
from pipeline.run.render import RenderRequest, render
from pipeline.scene import ElementMesh, read_scene
from pipeline.store import DIRECT_BIT
from pipeline.store.illumination import IlluminationMaps
from tests.stress.scenes import lit_room

RATIO = 1e6
N = 200_000


def _far_room_indirect(tmp, name, **kw):
    """Area-weighted mean indirect irradiance (RGB) of the dim lamp's room, and the frame."""
    path = lit_room(tmp / f"{name}.glb", dim_ratio=RATIO, **kw)
    out = tmp / name
    render(RenderRequest(scene_path=path, frames="1", out_dir=out, n_photons=N, temporal="off",
                         settings=RenderSettings(width=32, height=24, spp=1)), scheduler="synchronous")
    scene = read_scene(path)
    elements = ElementMesh.build(scene)
    state = scene.pose_frame(1)
    far = elements.vertex_positions(state)[:, 0] > 3.5
    areas = elements.vertex_areas(state)[far]
    indirect = IlluminationMaps.open(str(out / "photons.zarr")).read(0, "indirect")[far].astype(np.float64)
    return (indirect * areas[:, None]).sum(axis=0) / areas.sum(), read_exr(frame_paths(out, 1)[0])[0]


@pytest.fixture(scope="module")
def rooms(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("lights")
    return _far_room_indirect(tmp, "both"), _far_room_indirect(tmp, "dim", bright=False)


def test_dim_room_gets_its_own_indirect_light(rooms):
    (both, frame), (alone, _) = rooms
    assert alone.min() > 0
    # 5,000 photons of the dim lamp in the combined scene (10 % of the photons shared by 4 lights:
    # the point light, the spot, the panel and the dim lamp): about 2 % noise on the room's mean
    np.testing.assert_allclose(both, alone, rtol=0.08)
    assert all(np.isfinite(frame[c]).all() for c in frame)


def test_total_flux_is_unbiased_with_both_lights(tmp_path):
    scene = read_scene(lit_room(tmp_path / "both.glb", dim_ratio=RATIO))
    elements = ElementMesh.build(scene)
    state = scene.pose_frame(1)
    batch = trace_batch(state, elements, PhotonRange(1, 0, N), PhotonConfig(seed=3, photon_depth=256))
    direct = (batch.key & DIRECT_BIT) > 0
    flux = batch.energy[direct].astype(np.float64).sum(axis=0) / N
    # every photon's first hit is on a wall (closed rooms): the direct records carry all the flux
    expected = sum(li.power(1.0) for li in state.lights) + sum(
        np.pi * np.asarray(state.materials[state.triangle_material[t]].emission) * a
        for t, a in zip(state.emissive_triangles, _areas(state)[state.emissive_triangles]))
    np.testing.assert_allclose(flux, expected, rtol=0.03)


def _areas(state):
    c = state.vertices[state.faces].astype(np.float64)
    return 0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)


def test_selection_probability_floor():
    from pipeline.photons.emission import LIGHT_FLOOR, selection_probability

    # a lamp, a 1e6x dimmer lamp, and an emissive material of three triangles (one light)
    weight = np.array([1e6, 1.0, 2.0, 1.0, 1.0])
    group = np.array([0, 1, 5, 5, 5])
    p = selection_probability(weight, group)
    assert np.isclose(p.sum(), 1.0)
    assert p[1] >= LIGHT_FLOOR / 3  # every light gets its floor share
    np.testing.assert_allclose(p[2:] / p[2:].sum(), [0.5, 0.25, 0.25])  # by power inside a light
    assert p[0] > 0.9  # the rest by power
    # a light that emits nothing gets nothing
    assert selection_probability(np.array([1.0, 0.0]), np.array([0, 1]))[1] == 0
