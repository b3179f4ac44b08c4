"""The compositor against analytic values (real Embree): direct light, shadows, mirrors, area lights.

Expected values are evaluated at the exact jittered sample positions the compositor uses (its
counter-based random numbers), so the comparison has no sampling error for punctual lights.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kernels.camera import camera_rays_reference
from pipeline.frames.camera_paths import CHUNK_RAYS, CameraPaths, render_frame
from pipeline.frames.pixel_samples import sample_means
from pipeline.scene import ElementMesh, read_scene
from tests.frames.scenes import EYE, LAMP, area_scene, mirror_scene, plane_scene

W, H, SPP = 40, 30, 4
PATHS = CameraPaths(W, H, SPP, seed=3, frame=1)


def _render(path, irradiance=None, chunk_rays=CHUNK_RAYS, **kw):
    """The state of frame 1, its image along PATHS with ``kw`` changed, and those paths."""
    scene = read_scene(path)
    state = scene.pose_frame(1)
    elements = ElementMesh.build(scene)
    paths = replace(PATHS, **kw)
    return state, render_frame(state, elements, irradiance, paths, chunk_rays=chunk_rays), paths


def _sample_points(state, paths):
    """(H, W, spp, 3) points where the compositor's camera samples meet the plane y = 0."""
    cam = state.camera
    n = paths.width * paths.height * paths.spp
    d = camera_rays_reference(paths.key, 0, n, paths.spp, paths.width, paths.height,
                              cam.definition.yfov, cam.to_world[:3, :3]).astype(np.float64)
    origin = cam.position
    t = -origin[1] / d[:, 1]
    return (origin + t[:, None] * d).reshape(paths.height, paths.width, paths.spp, 3)


def _point_irradiance(p, lamp, intensity):
    delta = lamp - p
    r2 = (delta ** 2).sum(-1)
    return intensity * (delta[..., 1] / np.sqrt(r2)) / r2  # I cos(theta) / r^2


@pytest.mark.parametrize("light", ["point", "spot", "directional"])
def test_diffuse_plane_direct_radiance_is_analytic(tmp_path, light):
    albedo = np.array([0.5, 0.6, 0.7])
    state, img, paths = _render(plane_scene(tmp_path / "p.glb", light=light, albedo=albedo))
    p = _sample_points(state, paths)
    if light == "point":
        e = _point_irradiance(p, LAMP, 1.0)[..., None] * [10.0, 9.0, 8.0]
    elif light == "spot":  # glTF fall-off: squared linear ramp of cos between outer and inner cone
        axis = np.array([0.0, -1.0, 0.0])
        to_p = (p - LAMP) / np.linalg.norm(p - LAMP, axis=-1, keepdims=True)
        ramp = np.clip((to_p @ axis - np.cos(0.7)) / (np.cos(0.3) - np.cos(0.7)), 0, 1)
        e = (_point_irradiance(p, LAMP, 20.0) * ramp ** 2)[..., None] * np.ones(3)
    else:
        e = np.full(p.shape[:3] + (3,), 3.0 * np.cos(0.5))
    expected = (albedo / np.pi * e).mean(axis=2)  # pixel = mean over its samples
    lit = expected.max(axis=-1) > 1e-3
    assert lit.sum() > 100
    np.testing.assert_allclose(img.direct[lit], expected[lit], rtol=0.01)
    assert np.all(img.indirect == 0) and np.array_equal(img.beauty, img.direct)
    np.testing.assert_allclose(img.albedo, np.broadcast_to(albedo, img.albedo.shape), rtol=1e-6)
    # no specular material, no emitter: no reflection or area-light rays
    assert img.rays["camera"] == W * H * SPP and img.rays["area"] == img.rays["reflection"] == 0


def test_glossy_highlight_of_a_point_light_is_analytic(tmp_path):
    rho, roughness = np.array([0.9, 0.8, 0.7]), 0.4
    path = plane_scene(tmp_path / "g.glb", albedo=rho, roughness=roughness)
    state, img, paths = _render(path, max_depth=1)
    p = _sample_points(state, paths)
    view = (p - EYE) / np.linalg.norm(p - EYE, axis=-1, keepdims=True)
    mirror = view * [1, -1, 1]  # reflected about the plane's normal +y
    to_lamp = (LAMP - p) / np.linalg.norm(LAMP - p, axis=-1, keepdims=True)
    e = 2.0 / (roughness ** 2) ** 2 - 2.0  # Phong exponent of the material mapping
    brdf = (e + 2) / (2 * np.pi) * np.maximum((mirror * to_lamp).sum(-1), 0) ** e
    expected = (brdf * _point_irradiance(p, LAMP, 1.0))[..., None] * rho * [10.0, 9.0, 8.0]
    expected = expected.mean(axis=2)
    bright = expected.max(axis=-1) > 0.01 * expected.max()
    assert bright.sum() > 20
    # the lobe samples of depth 1 leave the scene (nothing else to reflect): only the highlight
    np.testing.assert_allclose(img.direct[bright], expected[bright], rtol=0.01)
    assert img.rays["reflection"] > 0 and np.all(img.indirect == 0)


def test_fully_occluded_pixels_have_no_direct_light(tmp_path):
    state, img, paths = _render(plane_scene(tmp_path / "o.glb", occluder=True))
    p = _sample_points(state, paths)
    # Where the segment from a plane point to the lamp crosses y = 1 (the occluder's plane)
    s = (1.0 - p[..., 1]) / (LAMP[1] - p[..., 1])
    x = p + s[..., None] * (LAMP - p)
    inside = (np.abs(x[..., 0] - 0.5) < 0.28) & (np.abs(x[..., 2] - 0.3) < 0.28)
    outside = (np.abs(x[..., 0] - 0.5) > 0.32) | (np.abs(x[..., 2] - 0.3) > 0.32)
    # Pixels seeing the plane (not the occluder's top) with every sample in the shadow
    c = EYE + (p - EYE) * (2.0 / 3.0)  # where the camera ray crosses y = 1
    camera_hits_plane = (np.abs(c[..., 0] - 0.5) > 0.32) | (np.abs(c[..., 2] - 0.3) > 0.32)
    shadowed = (inside & camera_hits_plane).all(axis=2)
    lit = (outside & camera_hits_plane).all(axis=2)
    assert shadowed.sum() >= 4 and lit.sum() > 100
    assert np.all(img.direct[shadowed] == 0)
    assert np.all(img.direct[lit] > 0)


def test_mirror_shows_the_colour_of_what_it_faces(tmp_path):
    _, img, _ = _render(mirror_scene(tmp_path / "m.glb"), max_depth=2)
    expected = np.array([0.8, 0.9, 0.7]) * np.array([2.0, 1.0, 0.5])
    np.testing.assert_allclose(img.beauty.reshape(-1, 3), np.broadcast_to(expected, (W * H, 3)),
                               rtol=1e-6)
    assert img.rays["reflection"] == W * H * SPP and img.rays["area"] == 0
    # Without reflection depth the mirror is black
    _, flat, _ = _render(mirror_scene(tmp_path / "m0.glb"), max_depth=0)
    assert np.all(flat.beauty == 0) and flat.rays["reflection"] == 0


def test_area_light_irradiance_below_a_square_emitter(tmp_path):
    half, height, radiance = 0.5, 1.0, 3.0
    _, img, _ = _render(area_scene(tmp_path / "a.glb", half, height, radiance), width=8, height=8,
                        spp=16, area_samples=2)
    x = half / height  # unit square corners: E = 4 L X/sqrt(1+X^2) atan(X/sqrt(1+X^2)) (view factor)
    e = 4 * radiance * x / np.sqrt(1 + x * x) * np.arctan(x / np.sqrt(1 + x * x))
    assert img.rays["area"] > 0
    np.testing.assert_allclose(img.direct.mean(axis=(0, 1)), 0.5 / np.pi * e, rtol=0.03)


def test_indirect_is_the_interpolated_map(tmp_path):
    path = plane_scene(tmp_path / "i.glb", albedo=(0.5, 0.5, 0.5))
    scene = read_scene(path)
    elements = ElementMesh.build(scene)
    irradiance = np.full((elements.n_vertices, 3), 2.0)  # constant irradiance 2 everywhere
    _, img, _ = _render(path, irradiance)
    np.testing.assert_allclose(img.indirect, 0.5 / np.pi * 2.0, rtol=1e-6)
    np.testing.assert_allclose(img.beauty, img.direct + img.indirect, rtol=1e-6)


def test_same_inputs_give_identical_pixels_whatever_the_chunking(tmp_path):
    path = area_scene(tmp_path / "d.glb")  # random numbers in jitter and area-light samples
    _, a, _ = _render(path, width=16, height=12)
    _, b, _ = _render(path, width=16, height=12, chunk_rays=100)
    _, c, _ = _render(path, width=16, height=12, seed=4)
    assert np.array_equal(a.beauty, b.beauty) and a.rays == b.rays
    assert not np.array_equal(a.beauty, c.beauty)  # the seed moves the jitter and the samples


def test_emitters_shine_from_their_front_face_only(tmp_path):
    # The panel faces down: from above, the camera sees its back, which neither shows emission
    # nor lights anything up there
    _, img, _ = _render(area_scene(tmp_path / "e.glb", eye=(0.0, 2.0, 0.0)), width=8, height=8)
    assert img.alpha.min() == 1 and np.all(img.beauty == 0)
    _, below, _ = _render(area_scene(tmp_path / "f.glb", eye=(0.0, 0.99, 0.0)), width=8, height=8)
    assert np.all(below.beauty > 0)  # from below the panel, the plane is lit


@pytest.mark.parametrize("spp", [1, 2, 3, 4, 8, 9, 16])
def test_sample_means_are_the_bits_of_numpys_mean(spp):
    """A pixel's layers are the mean of its samples; summed in sample order they are the bits of
    numpy's mean over the strided axis, which the frames were written with before."""
    rng = np.random.default_rng(spp)
    samples = (rng.random((3, 500, spp, 3)) * np.exp(rng.normal(0.0, 4.0, (3, 500, spp, 3)))).astype(np.float32)
    out = np.full((3, 500, 3), np.nan, np.float32)
    sample_means(samples, out)
    np.testing.assert_array_equal(out, samples.mean(axis=2))


@pytest.mark.parametrize("spp", [1, 4])
def test_maps_rendered_along_one_set_of_paths_have_the_bits_of_their_own_renders(tmp_path, spp):
    # The AQM's I1, I2 (pipeline/segments/halves.py) share camera paths: each layer must be the
    # render of its map alone, through metal and glossy bounces too (paths scattered back into samples)
    from pipeline.scene.builtin import write_builtin

    scene = read_scene(write_builtin("room", tmp_path / "room.glb"))  # diffuse, glossy and metal surfaces
    state, elements = scene.pose_frame(1), ElementMesh.build(scene)
    rng = np.random.default_rng(5)
    maps = [rng.uniform(0.0, 2.0, (elements.n_vertices, 3)) for _ in range(3)]
    paths = replace(PATHS, spp=spp)
    alone = [render_frame(state, elements, m, paths) for m in maps]
    shared = render_frame(state, elements, maps[0], paths, also_maps=np.stack(maps[1:]))  # rows of a stack
    assert shared.rays == alone[0].rays and shared.rays["reflection"] > 0
    assert np.array_equal(shared.beauty, alone[0].beauty) and np.array_equal(shared.indirect, alone[0].indirect)
    for i, one in enumerate(alone[1:]):
        assert np.array_equal(shared.also_indirect[i], one.indirect)
        assert np.array_equal(shared.also_beauty(i), one.beauty)
    assert not np.array_equal(alone[1].indirect, alone[2].indirect)  # the maps do show
    with pytest.raises(ValueError):
        render_frame(state, elements, None, paths, also_maps=maps[1:])
