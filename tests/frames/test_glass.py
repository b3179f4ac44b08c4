"""Solid glass (KHR_materials_transmission with KHR_materials_volume: a refracting, absorbing dielectric)
against closed forms: a camera sees an emitter through a face-on slab at (1 - F0)^2 (1 + F0^2) of its
radiance (two surfaces, one inner reflection pair within four reflections); a glass ball under a
sun focuses its light near the paraxial focus of a ball lens, n R / (2 (n - 1)) from its centre,
where the photons' density is many times the unobstructed one; `loom info` names it, a negative
thickness is a one-line error."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh
from click.testing import CliRunner
from pygltflib import Camera, Orthographic

from kernels.record_layout import ELEMENT_MASK
from pipeline.cli import main
from pipeline.config import PhotonConfig
from pipeline.errors import SceneError
from pipeline.frames.camera_paths import CameraPaths, render_frame
from pipeline.photons.tracing import PhotonRange, trace_batch
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.builtin.gltf_builder import GltfBuilder
from tests.conftest import QUAD, QUAD_FACES

F0 = 0.04  # ior 1.5
DOWN = (-0.7071068, 0, 0, 0.7071068)


def _glass(b: GltfBuilder, thickness: float = 1.0, ior: float = 1.5, attenuation=None) -> int:
    glass = b.add_material("glass", (1.0, 1.0, 1.0), roughness=0.0)
    volume = {"thicknessFactor": thickness}
    if attenuation is not None:  # (colour, distance)
        volume.update(attenuationColor=list(attenuation[0]), attenuationDistance=attenuation[1])
    b.gltf.materials[glass].extensions.update({
        "KHR_materials_transmission": {"transmissionFactor": 1.0}, "KHR_materials_ior": {"ior": ior},
        "KHR_materials_volume": volume})
    for name in ("KHR_materials_transmission", "KHR_materials_ior", "KHR_materials_volume"):
        b._use_extension(name)
    return glass


def slab_scene(path, *, glass=True, attenuation=None):
    """A 2 x 2 m emitter of radiance 1 at z = 0 facing +z, a 3 x 3 x 0.2 m glass slab in front of it,
    seen face-on by an orthographic camera at z = 5 (a view 4 m high: 8 pixels a metre at 32 rows)."""
    b = GltfBuilder()
    square = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    b.add_node("panel", b.add_mesh("panel", square, np.array([[0, 1, 2], [0, 2, 3]]),
                                   material=b.add_material("glow", (0, 0, 0), emissive=(1, 1, 1))))
    if glass:
        box = trimesh.creation.box(extents=(3, 3, 0.2))
        b.add_node("slab", b.add_mesh("slab", np.asarray(box.vertices), np.asarray(box.faces),
                                      material=_glass(b, attenuation=attenuation)), translation=(0, 0, 1))
    b.gltf.cameras.append(Camera(name="front", type="orthographic",
                                 orthographic=Orthographic(xmag=4.0, ymag=2.0, znear=0.0, zfar=10.0)))
    b.add_node("front_view", camera=0, translation=(0, 0, 5))
    return b.write(path)


def test_a_slab_passes_one_minus_f0_squared_of_what_is_behind_it(tmp_path):
    seen = []
    for glass in (False, True):
        scene = read_scene(slab_scene(tmp_path / f"slab{glass}.glb", glass=glass))
        img = render_frame(scene.pose_frame(1), None, None, CameraPaths(64, 32, 8, 0, 1))
        seen.append(img.direct[10:22, 26:38, 0])  # inside the emitter's 16 x 16 pixels
    assert seen[0].min() == pytest.approx(1.0)
    want = (1 - F0) ** 2 * (1 + F0**2)
    assert abs(seen[1].mean() - want) < 0.025, seen[1].mean()  # 1,152 samples of about Bernoulli(0.92)


def test_coloured_glass_keeps_its_attenuation_colour_over_its_attenuation_distance(tmp_path):
    # attenuationColor (1, 0.5, 0.25) over 0.2 m, the slab's thickness: one crossing keeps that colour
    scene = read_scene(slab_scene(tmp_path / "tinted.glb", attenuation=((1.0, 0.5, 0.25), 0.2)))
    img = render_frame(scene.pose_frame(1), None, None, CameraPaths(64, 32, 8, 0, 1))
    seen = img.direct[10:22, 26:38].reshape(-1, 3).mean(axis=0)
    c = np.array([1.0, 0.5, 0.25])
    want = (1 - F0) ** 2 * c * (1 + F0**2 * c**2)  # the inner reflection pair crosses twice more
    np.testing.assert_allclose(seen / seen[0], want / want[0], rtol=3e-3)  # c per crossing (c^3 on 1 path in 600)
    assert abs(seen[0] - want[0]) < 0.025


def ball_scene(path, *, ball=True, radius=0.5):
    """A 4 x 4 m floor lit by a sun straight above, a glass ball of ``radius`` centred 1.5 radius
    above it (where a ball lens of ior 1.5 focuses parallel light), elements of 5 cm."""
    b = GltfBuilder()
    b.add_node("floor", b.add_mesh("floor", QUAD * [2, 1, 2] - [2, 0, 2], QUAD_FACES,
                                   material=b.add_material("white", (0.7, 0.7, 0.7))))
    if ball:
        sphere = trimesh.creation.icosphere(subdivisions=4, radius=radius)
        b.add_node("ball", b.add_mesh("ball", np.asarray(sphere.vertices), np.asarray(sphere.faces),
                                      material=_glass(b), normals=np.asarray(sphere.vertices) / radius),
                   translation=(0, 1.5 * radius, 0))
    b.add_node("sun", light=b.add_directional_light("sun", (1, 1, 1), 3.0), rotation=DOWN)
    b.set_scene_extras({"photonloom": {"element_size": 0.05}})
    return b.write(path)


def test_a_glass_ball_focuses_sunlight_near_its_paraxial_focus(tmp_path):
    density = []
    for ball in (False, True):
        scene = read_scene(ball_scene(tmp_path / f"ball{ball}.glb", ball=ball))
        elements = ElementMesh.build(scene)
        state = scene.pose(0)
        batch = trace_batch(state, elements, PhotonRange(1, 0, 200_000), PhotonConfig())
        centre = elements.element_positions(state).mean(axis=1)[batch.key & ELEMENT_MASK]
        near = np.hypot(centre[:, 0], centre[:, 2]) < 0.05
        density.append(batch.energy[near].sum())
    assert density[1] > 10 * density[0], density  # focused: many times the sun's own (37x measured)
    assert read_scene(ball_scene(tmp_path / "b.glb")).materials[1].kind == "dielectric"


def test_info_names_refracting_glass_and_a_negative_thickness_is_an_error(tmp_path):
    path = ball_scene(tmp_path / "ball.glb")
    info = CliRunner().invoke(main, ["info", str(path)])
    assert info.exit_code == 0, info.output
    assert "refracting glass (KHR_materials_volume) on 1 material(s)" in info.output
    assert "KHR_materials_volume: not implemented" not in info.output
    b = GltfBuilder()
    glass = _glass(b, thickness=-1.0)
    b.add_node("slab", b.add_mesh("slab", QUAD, QUAD_FACES, material=glass))
    with pytest.raises(SceneError, match=r"materials\[0\].extensions.KHR_materials_volume.thicknessFactor: must be "
                                         r"a non-negative number, got -1.0"):
        read_scene(b.write(tmp_path / "bad.glb"))


def test_photons_through_coloured_glass_keep_its_colour(tmp_path):
    # A sun straight down through a 0.2 m slab of attenuationColor (1, 0.5, 0.25) over 0.2 m onto a
    # black floor (which records the photons' first arrival only)
    b = GltfBuilder()
    b.add_node("floor", b.add_mesh("floor", QUAD * [2, 1, 2] - [2, 0, 2], QUAD_FACES,
                                   material=b.add_material("black", (0.0, 0.0, 0.0))))
    box = trimesh.creation.box(extents=(4.5, 0.2, 4.5))
    b.add_node("slab", b.add_mesh("slab", np.asarray(box.vertices), np.asarray(box.faces),
                                  material=_glass(b, attenuation=((1.0, 0.5, 0.25), 0.2))), translation=(0, 1, 0))
    b.add_node("sun", light=b.add_directional_light("sun", (1, 1, 1), 3.0), rotation=DOWN)
    scene = read_scene(b.write(tmp_path / "tinted_sun.glb"))
    state = scene.pose(0)
    batch = trace_batch(state, ElementMesh.build(scene), PhotonRange(1, 0, 50_000), PhotonConfig())
    energy = batch.energy.sum(axis=0)  # every record is on the floor, under the slab
    np.testing.assert_allclose(energy[1:] / energy[0], [0.5, 0.25], rtol=2e-3)  # c^3 on 1 path in 600
