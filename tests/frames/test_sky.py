"""The default sun and the uniform sky against closed forms, in the photon tracer and the compositor.

* Compositor (real Embree shadow rays): a diffuse plane facing up under a sky of radiance L shows
  rho L exactly (cosine-weighted sky samples all reach an open sky); under the sun rho/pi x
  E sin(elevation) exactly; under a square occluder, rho L (1 - F) with F the view factor of the
  square (Howell's catalogue, C-11: differential area to a parallel rectangle); rays that miss the
  scene show the sky's radiance of their direction.
* Photon tracer (OpenCL kernels on PoCL): the direct records on that plane estimate pi L from the
  sky above, pi G from the ground half below (the plane records both faces), E sin(elevation) from
  the sun; and the furnace: a closed, non-convex white (albedo 1) solid under a sky of the same
  radiance L above and below has irradiance pi L on every face, direct plus indirect (the concave
  faces get less than pi L directly and the rest by interreflection).
"""
from __future__ import annotations

import numpy as np
import pytest

from kernels.camera import camera_rays_reference
from pipeline.collection.estimators import vertex_irradiance
from pipeline.config import PhotonConfig
from pipeline.frames.camera_paths import CameraPaths, render_frame
from pipeline.frames.random_numbers import frame_key
from pipeline.photons.tracing import PhotonRange, trace_batch
from pipeline.scene import ElementMesh, Scene, read_scene
from pipeline.scene.builtin.gltf_builder import GltfBuilder
from pipeline.scene.builtin.shapes import look_at, merge, quad
from pipeline.scene.default_lights import SUN_COLOR, SUN_ELEVATION, SUN_IRRADIANCE, default_sun
from pipeline.scene.sky import Sky
from tests.frames.scenes import UP_FACES, quad_y

ALBEDO = np.array([0.5, 0.6, 0.7])
ZENITH = (0.2, 0.3, 0.4)
GROUND = (0.05, 0.04, 0.03)


def _unlit_plane(path, half=2.0, camera=None, occluder=None, albedo=ALBEDO):
    """A diffuse plane at y = 0 (front face up) with no light; optionally a camera (eye, target,
    yfov) and a square occluder (half size, height) centred above the origin."""
    b = GltfBuilder()
    b.add_node("plane", b.add_mesh("plane", quad_y(half), UP_FACES, material=b.add_material("plane", albedo)))
    if occluder is not None:
        grey = b.add_material("occluder", (0.5, 0.5, 0.5))
        b.add_node("occluder", b.add_mesh("occluder", quad_y(occluder[0], occluder[1]), UP_FACES, material=grey))
    if camera is not None:
        eye, target, yfov = camera
        up = (0.0, 0.0, -1.0) if eye[1] != target[1] else (0.0, 1.0, 0.0)
        b.add_node("cam", camera=b.add_camera("cam", yfov, 0.01), translation=tuple(eye),
                   rotation=look_at(eye, target, up))
    b.set_scene_extras({"photonloom": {"element_size": 2.0 * half}})
    return b.write(path)


def _lit(path, *, sun: bool, sky: Sky | None) -> Scene:
    """The file loaded with its default lights replaced by the sun alone, a sky alone, or both."""
    scene = read_scene(path)
    assert scene.default_lights and scene.sky is not None  # the file has no light
    scene.default_lights = (default_sun(),) if sun else ()
    scene.sky = sky
    return scene


SUN_E = SUN_IRRADIANCE * np.array(SUN_COLOR) * np.sin(np.radians(SUN_ELEVATION))  # the default sun, horizontal


@pytest.mark.parametrize("case", ["sky", "sun", "both"])
def test_plane_direct_radiance_under_sun_and_sky_is_analytic(tmp_path, case):
    scene = _lit(_unlit_plane(tmp_path / "p.glb"), sun=case != "sky",
                 sky=None if case == "sun" else Sky(ZENITH, GROUND))
    state = scene.pose_frame(1)  # the auto camera: the plane from 20 degrees above its horizon
    img = render_frame(state, None, None, CameraPaths(48, 32, 2, seed=5, frame=1, area_samples=3))
    e = {"sky": np.pi * np.array(ZENITH), "sun": SUN_E, "both": SUN_E + np.pi * np.array(ZENITH)}[case]
    on = img.alpha == 1.0
    assert on.sum() > 100
    np.testing.assert_allclose(img.direct[on], np.broadcast_to(ALBEDO / np.pi * e, img.direct[on].shape), rtol=2e-5)
    hits = int(round(img.alpha.sum() * 2))  # camera samples on the plane
    assert img.rays["area"] == (0 if case == "sun" else hits * 3)  # 3 sky rays a diffuse hit


def test_rays_leaving_the_scene_show_the_sky(tmp_path):
    """Camera at the plane's height + 1 looking at the horizon: misses above the horizon show the
    zenith radiance, below it the ground's (spp 1, so each pixel is one ray)."""
    eye, target, yfov = (0.0, 1.0, 5.0), (0.0, 1.0, -5.0), 0.9
    scene = _lit(_unlit_plane(tmp_path / "h.glb", camera=(eye, target, yfov)), sun=True, sky=Sky(ZENITH, GROUND))
    state = scene.pose_frame(1)
    w, h = 40, 30
    img = render_frame(state, None, None, CameraPaths(w, h, 1, seed=2, frame=1))
    cam = state.camera
    d = camera_rays_reference(frame_key(2, 1), 0, w * h, 1, w, h, cam.definition.yfov,
                              cam.to_world[:3, :3]).reshape(h, w, 3)
    miss = img.alpha == 0
    up = d[..., 1] >= 0
    assert (miss & up).sum() > 100 and (miss & ~up).sum() > 20 and (~miss).sum() > 100
    np.testing.assert_array_equal(img.direct[miss & up], np.broadcast_to(np.float32(ZENITH), ((miss & up).sum(), 3)))
    np.testing.assert_array_equal(img.direct[miss & ~up], np.broadcast_to(np.float32(GROUND), ((miss & ~up).sum(), 3)))
    np.testing.assert_array_equal(img.albedo[miss], 0.0)


def test_a_mirror_reflects_the_sky(tmp_path):
    """An ideal mirror floor seen from above its horizon reflects rays upwards: reflectance x the
    zenith radiance, exactly (no light reaches an ideal mirror but through its reflection)."""
    b = GltfBuilder()
    mirror = b.add_material("mirror", ALBEDO, metallic=1.0, roughness=0.0)
    b.add_node("plane", b.add_mesh("plane", quad_y(2.0), UP_FACES, material=mirror))
    scene = _lit(b.write(tmp_path / "m.glb"), sun=True, sky=Sky(ZENITH, GROUND))
    img = render_frame(scene.pose_frame(1), None, None, CameraPaths(32, 24, 1, seed=1, frame=1))
    on = img.alpha == 1.0
    assert on.sum() > 30
    np.testing.assert_allclose(img.direct[on], np.broadcast_to(ALBEDO * np.array(ZENITH), (on.sum(), 3)), rtol=1e-6)


def _square_view_factor(a: float, h: float) -> float:
    """View factor from a differential area to a parallel square of half side a centred h above
    it: four corner rectangles of Howell C-11, F = 1/(2 pi) [A/sqrt(1+A^2) atan(B/sqrt(1+A^2)) + (A<->B)]."""
    x = a / h
    corner = (1.0 / (2.0 * np.pi)) * 2.0 * (x / np.sqrt(1 + x * x)) * np.arctan(x / np.sqrt(1 + x * x))
    return 4.0 * corner


def test_sky_under_an_occluder_matches_the_view_factor(tmp_path):
    """A 1 x 1 square 1 above the plane hides F = 0.239 of the cosine-weighted sky of the point
    below its centre; the camera between them sees a few mm of plane (F constant there).
    Noise floor: 20 x 15 pixels x 16 spp x 16 sky rays, binomial, 0.2 % of (1 - F)."""
    path = _unlit_plane(tmp_path / "o.glb", half=10.0, camera=((0.0, 0.5, 0.0), (0.0, 0.0, 0.0), 0.01),
                        occluder=(0.5, 1.0))
    scene = _lit(path, sun=False, sky=Sky(ZENITH, (0.0, 0.0, 0.0)))
    img = render_frame(scene.pose_frame(1), None, None, CameraPaths(20, 15, 16, seed=9, frame=1, area_samples=16))
    f = _square_view_factor(0.5, 1.0)
    assert abs(f - 0.2394) < 1e-3
    expected = ALBEDO * np.array(ZENITH) * (1.0 - f)
    np.testing.assert_allclose(img.direct.reshape(-1, 3).mean(axis=0), expected, rtol=0.01)


# --- the photon tracer ---------------------------------------------------------------------------
def _triangle_irradiance(state, elements, n, batches, *, direct=None, max_depth=1, seed=0):
    """(batches, F, 3) irradiance of every source triangle from the records of ``batches``
    independent batches of n photons each (records of direct hits only, indirect only, or all)."""
    area = 0.5 * np.linalg.norm(np.cross(*(np.diff(state.vertices[state.faces].astype(np.float64), axis=1)
                                           .transpose(1, 0, 2))), axis=1)
    out = np.zeros((batches, len(state.faces), 3))
    for k in range(batches):
        b = trace_batch(state, elements, PhotonRange(1, k * n, n), PhotonConfig(seed=seed, photon_depth=max_depth))
        keep = np.ones(len(b.key), bool) if direct is None else ((b.key >> np.uint32(31)) == 1) == direct
        tri = elements.element_triangle[(b.key[keep] & np.uint32(0x3FFFFFFF)).astype(np.int64)]
        for c in range(3):
            out[k, :, c] = np.bincount(tri, weights=b.energy[keep, c], minlength=len(state.faces))
        out[k] /= n * area[:, None]
    return out


def _within_noise(batches: np.ndarray, expected, k: float = 4.0, floor: float = 0.02):
    """The mean over batches is within k standard errors (spread between batches) of ``expected``,
    and that standard error is below ``floor`` of it (the test can tell)."""
    mean = batches.mean(axis=0)
    se = batches.std(axis=0, ddof=1) / np.sqrt(len(batches))
    expected = np.broadcast_to(expected, mean.shape)
    assert np.all(se < floor * expected), (se, expected)
    assert np.all(np.abs(mean - expected) < k * se + 1e-9 * expected), (mean, expected, se)


@pytest.mark.parametrize("case", ["zenith", "ground", "sun"])
def test_photon_direct_irradiance_of_a_plane_under_sun_and_sky(tmp_path, case):
    sky = {"zenith": Sky(ZENITH, (0.0, 0.0, 0.0)), "ground": Sky((0.0, 0.0, 0.0), GROUND), "sun": None}[case]
    scene = _lit(_unlit_plane(tmp_path / "p.glb"), sun=case == "sun", sky=sky)
    state = scene.pose_frame(1)
    elements = ElementMesh.build(scene)
    e = _triangle_irradiance(state, elements, 60_000, 8, direct=True)
    expected = {"zenith": np.pi * np.array(ZENITH), "ground": np.pi * np.array(GROUND), "sun": SUN_E}[case]
    _within_noise(e.reshape(8, -1), np.tile(expected, len(state.faces)))


def _l_prism(path, albedo=(1.0, 1.0, 1.0)):
    """A closed solid of L-shaped section (2 x 2 with a 1 x 1 notch), 2 deep in z, faces outward,
    one quad (two triangles) per face; no light, no camera."""
    d = 2.0
    quads = [quad((0, 0, 0), (2, 0, 0), (0, 0, d)),   # bottom, -y
             quad((2, 0, 0), (0, 1, 0), (0, 0, d)),   # right, +x
             quad((1, 1, 0), (0, 0, d), (1, 0, 0)),   # step, +y (concave)
             quad((1, 1, 0), (0, 1, 0), (0, 0, d)),   # inner wall, +x (concave)
             quad((0, 2, 0), (0, 0, d), (1, 0, 0)),   # top, +y
             quad((0, 0, 0), (0, 0, d), (0, 2, 0)),   # left, -x
             quad((0, 0, 0), (0, 1, 0), (2, 0, 0)),   # back, -z (two rectangles)
             quad((0, 1, 0), (0, 1, 0), (1, 0, 0)),
             quad((0, 0, d), (2, 0, 0), (0, 1, 0)),   # front, +z
             quad((0, 1, d), (1, 0, 0), (0, 1, 0))]
    pos, idx = merge(quads)
    b = GltfBuilder()
    b.add_node("solid", b.add_mesh("solid", pos, idx, material=b.add_material("white", albedo)))
    b.set_scene_extras({"photonloom": {"element_size": 0.5}})
    return b.write(path)


CONCAVE = (2, 3)  # the step and the inner wall see each other


def test_photon_furnace_with_a_uniform_sky(tmp_path):
    """Every face of the white L solid has E = pi L (direct + indirect records); the concave faces'
    direct part alone is clearly less (so the indirect records carry the rest)."""
    level = (0.25, 0.25, 0.25)
    scene = _lit(_l_prism(tmp_path / "l.glb"), sun=False, sky=Sky(level, level))
    state = scene.pose_frame(1)
    elements = ElementMesh.build(scene)
    n, batches = 50_000, 8
    total = _triangle_irradiance(state, elements, n, batches, max_depth=16)
    direct = _triangle_irradiance(state, elements, n, batches, direct=True, max_depth=16)
    def faces(e):  # two equal triangles a face
        return e.reshape(batches, -1, 2, 3).sum(axis=2) / 2.0
    expected = np.pi * np.array(level)
    _within_noise(faces(total), np.broadcast_to(expected, (len(state.faces) // 2, 3)), floor=0.03)
    concave = faces(direct).mean(axis=0)[list(CONCAVE)]
    assert np.all(concave < 0.85 * expected)


def test_composited_furnace_makes_the_white_solid_vanish(tmp_path):
    """The compositor's direct light (sky shadow rays) plus its indirect term (the vertex map of
    the indirect records) give radiance L on the white solid, the sky's own radiance: the solid
    cannot be told from the background. On the concave faces (where the sky is partly hidden) the
    map supplies about a quarter of L; their mean is within 2 % (measured -0.4 %: the map's photon
    noise and its linear interpolation across the concave edge, where indirect light varies most)."""
    level = 0.25
    scene = _lit(_l_prism(tmp_path / "l.glb"), sun=False, sky=Sky((level,) * 3, (level,) * 3))
    state = scene.pose_frame(1)  # the auto camera sees the front, the step, the inner wall and the right side
    elements = ElementMesh.build(scene)
    n = 400_000
    b = trace_batch(state, elements, PhotonRange(1, 0, n), PhotonConfig(seed=1, photon_depth=16))
    indirect = (b.key >> np.uint32(31)) == 0
    element = (b.key[indirect] & np.uint32(0x3FFFFFFF)).astype(np.int64)
    e_map = vertex_irradiance(element, b.bary[indirect, 0], b.bary[indirect, 1], b.energy[indirect],
                              elements, elements.vertex_areas(state), n)
    img = render_frame(state, elements, e_map, CameraPaths(64, 48, 4, seed=3, frame=1, area_samples=8))
    on = img.alpha == 1.0
    shaded = on & (img.direct[..., 0] < 0.96 * level)  # the concave faces
    assert on.mean() > 0.2 and shaded.sum() > 150
    np.testing.assert_allclose(img.beauty[img.alpha == 0], level, rtol=1e-6)  # the background is the sky
    assert abs(img.beauty[on].mean() / level - 1.0) < 0.01
    assert abs(img.beauty[shaded].mean() / level - 1.0) < 0.02
    assert img.indirect[shaded].mean() > 0.15 * level  # the interreflection is in the map
