"""Metallic-roughness textures (pipeline/scene/shading.py ``SurfaceShading.kinds``): the texel at a hit
decides its kind and lobe, for photons and pixels alike. A floor whose texture makes its half x < 1 a
mirror and the rest diffuse: the kinds at hits; a lamp's photons recorded on the diffuse half only;
under a sun straight above, the direct light of the diffuse half equals the untextured floor's and
the mirror half has none; `loom info` counts the texture as read and says why occlusion textures are
not applied."""
from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from pygltflib import OcclusionTextureInfo

from kernels.record_layout import DIRECT_BIT, ELEMENT_MASK
from pipeline.cli import main
from pipeline.config import PhotonConfig
from pipeline.frames.images import frame_paths, read_exr
from pipeline.photons.raycast import caster_for
from pipeline.photons.tracing import PhotonRange, trace_batch
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.builtin.gltf_builder import GltfBuilder
from pipeline.scene.materials import phong_exponents
from pipeline.scene.shading import SurfaceShading
from tests.conftest import QUAD, QUAD_FACES, sun_and_camera_above

METAL_MIRROR, DIFFUSE = (0, 0, 255), (0, 255, 0)  # (R unused, G roughness, B metallic), linear bytes


def _texture(left, right) -> np.ndarray:
    """4 x 4 texels: columns 0-1 (u < 0.5) ``left``, 2-3 ``right``."""
    img = np.zeros((4, 4, 3), np.uint8)
    img[:, :2], img[:, 2:] = left, right
    return img


def floor(path, texels=None, *, metallic=1.0, roughness=1.0, sun=False, occlusion=False):
    """The 2 x 2 floor QUAD (normal +y), u = x / 2, v = z / 2, under a lamp (or a sun and a camera)."""
    b = GltfBuilder()
    uv = np.c_[QUAD[:, 0] / 2, QUAD[:, 2] / 2]
    # clamped: a repeating bilinear lookup would blend the halves again at the floor's edges
    tex = None if texels is None else b.add_texture(texels, wrap_s=33071, wrap_t=33071)
    mat = b.add_material("m", (0.5, 0.5, 0.5), metallic=metallic, roughness=roughness,
                         metallic_roughness_texture=tex)
    if occlusion:
        b.gltf.materials[mat].occlusionTexture = OcclusionTextureInfo(index=b.add_texture(_texture((0,) * 3, (0,) * 3)))
    b.add_node("floor", b.add_mesh("floor", QUAD, QUAD_FACES, material=mat, texcoords={0: uv}))
    if sun:
        sun_and_camera_above(b)
    else:
        b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 10.0), translation=(1, 2, 1))
    return b.write(path)


def _kinds(path, u):
    state = read_scene(path).pose_frame(1)
    surface = SurfaceShading(state, caster_for(state).normals)
    assert surface.kind_varies
    u = np.asarray(u, np.float64)
    return surface.kinds(np.zeros(len(u), np.int64), u, np.full(len(u), 0.05))


def test_the_texel_decides_the_kind(tmp_path):
    # triangle 0 of QUAD_FACES spans its corners 0, 1, 2: its barycentric u runs along x there
    path = floor(tmp_path / "half.glb", _texture(METAL_MIRROR, DIFFUSE))
    kind, _ = _kinds(path, [0.05, 0.2, 0.8, 0.9])
    state = read_scene(path).pose_frame(1)
    x = state.vertices[state.faces[0]][:, 0]
    at = (1 - np.array([0.05, 0.2, 0.8, 0.9]) - 0.05) * x[0] + np.array([0.05, 0.2, 0.8, 0.9]) * x[1] + 0.05 * x[2]
    np.testing.assert_array_equal(kind, np.where(at < 1, 1, 0))  # mirror where x < 1
    assert set(kind.tolist()) == {0, 1}


@pytest.mark.parametrize("green, metallic, roughness, want", [
    (102, 1.0, 1.0, 2),  # roughness 0.4: glossy
    (102, 0.4, 1.0, 0),  # metallic 0.4 x 1: diffuse
    (204, 1.0, 0.5, 2),  # roughness 0.5 x 0.8 = 0.4: glossy
    (255, 1.0, 0.1, 1),  # roughness 0.1 x 1: a mirror
])
def test_the_factors_scale_the_texel(tmp_path, green, metallic, roughness, want):
    texel = (0, green, 255)
    kind, exponent = _kinds(floor(tmp_path / "f.glb", _texture(texel, texel), metallic=metallic,
                                  roughness=roughness), [0.3, 0.6])
    assert kind.tolist() == [want] * 2
    r = roughness * green / 255
    np.testing.assert_allclose(exponent, phong_exponents(np.full(2, r)), rtol=1e-5)


def test_photons_are_recorded_on_the_diffuse_texels_only(tmp_path):
    scene = read_scene(floor(tmp_path / "half.glb", _texture(METAL_MIRROR, DIFFUSE)))
    elements = ElementMesh.build(scene)
    batch = trace_batch(scene.pose(0), elements, PhotonRange(1, 0, 20_000), PhotonConfig())
    direct = (batch.key & DIRECT_BIT) != 0
    centre = elements.element_positions(scene.pose(0)).mean(axis=1)[batch.key[direct] & ELEMENT_MASK]
    assert (centre[:, 0] > 1.1).sum() > 200 and (centre[:, 0] < 0.9).sum() == 0
    assert read_scene(floor(tmp_path / "plain.glb")).materials[0].is_specular is False
    assert scene.materials[0].is_specular and scene.has_specular  # its texels make it reflect: rays are traced


def test_the_mirror_half_takes_no_direct_light(tmp_path):
    direct = []
    for name, texels in (("plain", None), ("half", _texture(METAL_MIRROR, DIFFUSE))):
        out = tmp_path / name
        result = CliRunner().invoke(main, ["render", str(floor(tmp_path / f"{name}.glb", texels, sun=True)),
                                           "--out", str(out), "--frames", "1", "--photons", "2000", "--temporal",
                                           "off", "--resolution", "32x24", "--spp", "1", "--scheduler",
                                           "synchronous", "--quiet"])
        assert result.exit_code == 0, result.output
        direct.append(read_exr(frame_paths(out, 1)[0])[0]["direct.R"])
    plain, half = direct
    lit = plain > 0
    columns = np.arange(plain.shape[1])[None, :].repeat(plain.shape[0], axis=0)
    left, right = lit & (columns < 14), lit & (columns > 17)  # the camera's +x is the image's right
    assert left.sum() > 50 and right.sum() > 50
    np.testing.assert_array_equal(half[right], plain[right])  # diffuse: the same pixels to the bit
    assert half[left].max() == 0.0  # a mirror reflects the sun nowhere the camera sees it


def test_info_reads_the_texture_and_says_why_occlusion_is_not_applied(tmp_path):
    path = floor(tmp_path / "f.glb", _texture(METAL_MIRROR, DIFFUSE), occlusion=True)
    info = CliRunner().invoke(main, ["info", str(path)])
    assert info.exit_code == 0, info.output
    assert "metallic-roughness textures on 1 material(s)" in info.output
    assert "metallicRoughnessTexture" not in info.output
    assert "occlusionTexture on 1" in info.output and "the photons compute occlusion" in info.output
