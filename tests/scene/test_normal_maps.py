"""Normal maps (pipeline/scene/shading.py ``SurfaceShading._bent``) against closed forms: a floor
whose map holds one tangent-space normal (sin a, 0, cos a) shades about the normal tilted by a
towards its dp/du, (0, sin a, cos a) towards decreasing v, scaled by normalTexture.scale, mirrored
with mirrored texture coordinates; and a rendered floor under a sun straight above gets cos a of
the direct light it gets without the map (a directional light's irradiance E cos)."""
from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from pipeline.cli import main
from pipeline.frames.images import frame_paths, read_exr
from pipeline.photons.raycast import caster_for
from pipeline.scene import read_scene
from pipeline.scene.builtin.gltf_builder import GltfBuilder
from pipeline.scene.shading import SurfaceShading
from tests.conftest import QUAD, QUAD_FACES, sun_and_camera_above

SIN, COS = 0.6, 0.8  # a = 36.87 deg, written exactly enough in 8 bits: (0.6 + 1) / 2 = 204 / 255


def _texel(tangent_space) -> np.ndarray:
    return np.tile(np.round((np.asarray(tangent_space) + 1) / 2 * 255).astype(np.uint8), (4, 4, 1))


def floor(path, tangent_space=None, *, scale=1.0, mirrored=False, sun=False, tangent=None, turned=None):
    """The 2 x 2 floor QUAD (normal +y) with u = x / 2 (or 1 - x / 2), v = z / 2, its map one texel;
    with ``tangent`` (x, y, z, w) its TANGENT (and NORMAL), the floor turned about +y by the
    quaternion ``turned`` by its node or, with ``turned=("skin", q)``, by a joint it is skinned to."""
    b = GltfBuilder()
    uv = np.c_[QUAD[:, 0] / 2, QUAD[:, 2] / 2]
    if mirrored:
        uv[:, 0] = 1 - uv[:, 0]
    normal = None if tangent_space is None else b.add_texture(_texel(tangent_space))
    mat = b.add_material("m", (0.5, 0.5, 0.5), normal_texture=normal, normal_scale=scale)
    normals = None if tangent is None else np.tile([0.0, 1.0, 0.0], (4, 1)).astype(np.float32)
    mesh = b.add_mesh("floor", QUAD, QUAD_FACES, material=mat, texcoords={0: uv}, normals=normals)
    if tangent is not None:
        b.gltf.meshes[mesh].primitives[0].attributes.TANGENT = b.add_accessor(
            np.tile(tangent, (4, 1)).astype(np.float32), target=34962)
    skinned = isinstance(turned, tuple) and turned[0] == "skin"
    node = b.add_node("floor", mesh, rotation=None if skinned else turned)
    if skinned:
        joint = b.add_node("bone", rotation=turned[1])
        b.gltf.nodes[node].skin = b.add_skin([joint])
        b.bind_skin(mesh, 0, np.zeros((4, 4), int), np.tile([1.0, 0, 0, 0], (4, 1)))
    if sun:
        sun_and_camera_above(b)
    else:
        b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 1.0), translation=(1, 2, 1))
    return b.write(path)


def _normals(path):
    state = read_scene(path).pose_frame(1)
    surface = SurfaceShading(state, caster_for(state).normals)
    u, v = np.array([0.1, 0.3, 0.6]), np.array([0.2, 0.5, 0.1])
    tri = np.flatnonzero(state.triangle_instance == 0)[[0, 1, 1]]
    return surface.normal(tri, u, v)


@pytest.mark.parametrize("tangent_space, scale, mirrored, want", [
    ((SIN, 0, COS), 1.0, False, (SIN, COS, 0)),  # towards +x, the way u grows
    ((0, SIN, COS), 1.0, False, (0, COS, -SIN)),  # towards -z, the way v falls (+Y is up in the image)
    ((SIN, 0, COS), 0.5, False, np.array([0.3, 0.8, 0]) / np.hypot(0.3, 0.8)),  # x and y scaled
    ((SIN, 0, COS), 1.0, True, (-SIN, COS, 0)),  # u grows towards -x
])
def test_a_constant_map_tilts_the_normal_as_its_closed_form(tmp_path, tangent_space, scale, mirrored, want):
    n = _normals(floor(tmp_path / "f.glb", tangent_space, scale=scale, mirrored=mirrored))
    np.testing.assert_allclose(n, [want] * 3, atol=0.006)  # 8-bit texels


TURN_Y = (0.0, 0.7071068, 0.0, 0.7071068)  # +90 degrees about +y: +z turns to +x


@pytest.mark.parametrize("tangent_space, tangent, turned, want", [
    ((SIN, 0, COS), (0, 0, 1, 1), None, (0, COS, SIN)),  # towards the file's tangent, +z, not dp/du's +x
    ((0, SIN, COS), (0, 0, 1, 1), None, (SIN, COS, 0)),  # the bitangent w (n x t) = +x
    ((0, SIN, COS), (0, 0, 1, -1), None, (-SIN, COS, 0)),  # w = -1: the other way
    ((SIN, 0, COS), (0, 0, 1, 1), TURN_Y, (SIN, COS, 0)),  # the node turns the tangent with it
    ((SIN, 0, COS), (0, 0, 1, 1), ("skin", TURN_Y), (SIN, COS, 0)),  # and so does the joint of a skin
])
def test_the_files_tangents_span_the_frame(tmp_path, tangent_space, tangent, turned, want):
    n = _normals(floor(tmp_path / "t.glb", tangent_space, tangent=tangent, turned=turned))
    np.testing.assert_allclose(n, [want] * 3, atol=0.006)


def test_a_flat_map_changes_nothing(tmp_path):
    np.testing.assert_allclose(_normals(floor(tmp_path / "f.glb", (0, 0, 1))), [[0, 1, 0]] * 3, atol=0.006)


def test_the_direct_light_of_a_tilted_normal_is_cos_a(tmp_path):
    direct = []
    for name, tangent_space in (("plain", None), ("tilted", (SIN, 0, COS))):
        path = floor(tmp_path / f"{name}.glb", tangent_space, sun=True)
        out = tmp_path / name
        result = CliRunner().invoke(main, ["render", str(path), "--out", str(out), "--frames", "1", "--photons",
                                           "2000", "--temporal", "off", "--resolution", "32x24", "--spp", "1",
                                           "--scheduler", "synchronous", "--quiet"])
        assert result.exit_code == 0, result.output
        direct.append(read_exr(frame_paths(out, 1)[0])[0]["direct.R"])
    lit = direct[0] > 0
    assert lit.sum() > 200  # the floor fills about a third of the frame
    np.testing.assert_allclose(direct[1][lit] / direct[0][lit], COS, rtol=0.01)
    info = CliRunner().invoke(main, ["info", str(tmp_path / "tilted.glb")])
    assert "normal maps on 1 material(s)" in info.output and "normalTexture" not in info.output
