"""Image-based lighting (pipeline/scene/environment.py) against closed forms: the map's directions
(Blender's equirectangular convention) and its importance sampling (pdf integrates to 1, a
one-texel map is sampled in that texel); an open floor under a constant map of radiance L has
irradiance pi L, in the compositor's direct light and in the photons' alike; under a map dark but
for one small bright texel, E_texel cos(theta), as under a sun; `loom render --environment`
renders an EXR map, `loom info` names it, a missing file is a one-line error."""
from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest
from click.testing import CliRunner

from kernels.record_layout import DIRECT_BIT, ELEMENT_MASK
from pipeline.cli import main
from pipeline.collection.estimators import vertex_irradiance
from pipeline.config import PhotonConfig
from pipeline.frames.camera_paths import CameraPaths, render_frame
from pipeline.photons.tracing import PhotonRange, trace_batch
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.builtin.gltf_builder import GltfBuilder
from pipeline.scene.environment import EnvironmentMap, texel_solid_angles
from tests.conftest import QUAD, QUAD_FACES

ALBEDO = 0.5
DOWN = (-0.7071068, 0, 0, 0.7071068)


def open_floor(path):
    """A 2 x 2 floor alone (nothing else to occlude the map), seen from straight above; single-sided,
    so the map's lower half, which would light its underside, is not gathered as its irradiance
    (a sheet has one irradiance for both faces: docs/14-robustness.md §8)."""
    b = GltfBuilder()
    grey = b.add_material("grey", (ALBEDO,) * 3, double_sided=False)
    b.add_node("floor", b.add_mesh("floor", QUAD, QUAD_FACES, material=grey))
    b.add_node("cam", camera=b.add_camera("cam", 0.5, 0.05), translation=(1, 3, 1), rotation=DOWN)
    b.set_scene_extras({"photonloom": {"element_size": 0.25}})
    return b.write(path)


def constant(radiance: float, h: int = 32, w: int = 64) -> EnvironmentMap:
    return EnvironmentMap(np.full((h, w, 3), radiance, np.float32), "c" * 64)


def one_texel(row: int, irradiance: float, h: int = 64, w: int = 128) -> EnvironmentMap:
    """Dark but for texel (row, w / 4): towards -Z (u = 1/4), the radiance that gives ``irradiance``
    face-on."""
    img = np.zeros((h, w, 3), np.float32)
    img[row, w // 4] = irradiance / texel_solid_angles(h, w)[row, 0]
    return EnvironmentMap(img, "d" * 64)


def test_directions_and_importance_sampling():
    env = one_texel(10, 3.0)
    i = env._texel(np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]))
    assert (i % 128).tolist()[:3] == [96, 64, 32] and i[3] // 128 == 0  # +Z at u 3/4, +X at 1/2, -Z at 1/4; +Y on top
    rng = np.random.default_rng(1)
    d, pdf = env.sample(rng.random(5000), rng.random(5000), rng.random(5000))
    assert set(env._texel(d).tolist()) == {10 * 128 + 32}
    np.testing.assert_allclose(env.pdf(d), pdf)
    d, pdf = constant(1.0).sample(rng.random(200_000), rng.random(200_000), rng.random(200_000))
    assert abs((1 / pdf).mean() - 4 * np.pi) < 1e-9  # uniform: the sphere's 4 pi
    assert abs(d[:, 1].mean()) < 0.01


def _direct_mean(path, env) -> float:
    scene = read_scene(path, environment=env)
    img = render_frame(scene.pose_frame(1), None, None, CameraPaths(32, 24, 8, 0, 1))
    floor = img.alpha > 0.99
    assert floor.sum() > 300
    return float(img.direct[floor, 0].mean())


def _photon_irradiance(path, env, n=200_000) -> np.ndarray:
    scene = read_scene(path, environment=env)
    state = scene.pose(0)
    elements = ElementMesh.build(scene)
    batch = trace_batch(state, elements, PhotonRange(1, 0, n), PhotonConfig())
    direct = (batch.key & DIRECT_BIT) != 0
    e = vertex_irradiance(batch.key[direct] & ELEMENT_MASK, batch.bary[direct, 0], batch.bary[direct, 1],
                          batch.energy[direct], elements, elements.vertex_areas(state), batch.photons_emitted)
    pos = elements.vertex_positions(state)
    inner = (np.abs(pos[:, 0] - 1) < 0.6) & (np.abs(pos[:, 2] - 1) < 0.6)
    return e[inner, 0]


def test_an_open_floor_under_a_constant_map_has_pi_l(tmp_path):
    path = open_floor(tmp_path / "floor.glb")
    env = constant(2.0)
    # the compositor: rho / pi x pi L
    assert _direct_mean(path, env) == pytest.approx(ALBEDO * 2.0, rel=0.03)
    # the photons: E = pi L at the floor's vertices (median of 200,000 photons' estimates)
    assert np.median(_photon_irradiance(path, env)) == pytest.approx(np.pi * 2.0, rel=0.05)


def test_one_bright_texel_lights_as_a_sun(tmp_path):
    # row 11 of 64: elevation about 56 deg; E_texel cos(theta) on the floor, theta from the zenith
    path = open_floor(tmp_path / "floor.glb")
    env = one_texel(11, 4.0)
    elevation = np.pi * (0.5 - 11.5 / 64)
    want = 4.0 * np.sin(elevation)
    assert _direct_mean(path, env) == pytest.approx(ALBEDO / np.pi * want, rel=0.02)
    assert np.median(_photon_irradiance(path, env, 100_000)) == pytest.approx(want, rel=0.03)


def test_loom_render_takes_an_exr_map(tmp_path):
    path = open_floor(tmp_path / "floor.glb")
    exr = tmp_path / "sky.exr"
    out = oiio.ImageOutput.create(str(exr))
    out.open(str(exr), oiio.ImageSpec(64, 32, 3, "float"))
    out.write_image(np.full((32, 64, 3), 2.0, np.float32))
    out.close()
    run = CliRunner().invoke(main, ["render", str(path), "--out", str(tmp_path / "out"), "--frames", "1",
                                    "--photons", "2000", "--temporal", "off", "--resolution", "16x12", "--spp", "2",
                                    "--environment", str(exr), "--environment-strength", "0.5",
                                    "--scheduler", "synchronous", "--quiet"])
    assert run.exit_code == 0, run.output
    info = CliRunner().invoke(main, ["info", str(path), "--environment", str(exr)])
    assert "an environment map around it, sky.exr (64x32, strength 1)" in info.output
    assert "default sun" not in info.output
    bad = CliRunner().invoke(main, ["info", str(path), "--environment", str(tmp_path / "none.exr")])
    assert bad.exit_code == 2 and "none.exr: --environment: cannot read the environment map" in bad.output
    assert len(bad.output.strip().splitlines()) == 1


def test_a_turned_map_turns_its_light(tmp_path):
    # the bright texel sits towards -Z; turned 90 degrees (right-hand rule about +Y) it lies towards -X
    env = one_texel(11, 4.0)
    turned = EnvironmentMap(env.image, env.digest, None, 90.0)
    rng = np.random.default_rng(3)
    d, _ = turned.sample(rng.random(2000), rng.random(2000), rng.random(2000))
    horizontal = d[:, [0, 2]] / np.linalg.norm(d[:, [0, 2]], axis=1, keepdims=True)
    assert np.abs(horizontal - [-1.0, 0.0]).max() < 0.05  # within the texel's width, 2 pi / 128 = 0.049
    np.testing.assert_array_equal(turned.radiance(d), env.radiance(np.c_[-d[:, 2], d[:, 1], d[:, 0]]))
    # what lights the floor does not depend on the turn about its normal
    path = open_floor(tmp_path / "floor.glb")
    assert _direct_mean(path, turned) == pytest.approx(_direct_mean(path, env), rel=0.02)
