"""Vertex attributes (NORMAL, TEXCOORD_0/1, COLOR_0), base-colour textures and samplers as loaded.

Images are real PNG/JPEG files written with OpenImageIO, embedded in the .glb or next to a .gltf.
"""
from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from pipeline.cli import main
from pipeline.errors import SceneError
from pipeline.photons.raycast import caster_for
from pipeline.scene import read_scene
from pipeline.scene.builtin.gltf_builder import GltfBuilder, encode_png
from pipeline.scene.shading import SurfaceShading
from pipeline.scene.textures import CLAMP_TO_EDGE, MIRRORED_REPEAT, REPEAT, Texture, sample, srgb_to_linear

QUAD = np.array([[0, 0, 0], [2, 0, 0], [2, 0, 2], [0, 0, 2]], float)
FACES = np.array([0, 2, 1, 0, 3, 2])
UV = QUAD[:, [0, 2]] / 2.0


def _builder(material=None, **mesh):
    b = GltfBuilder()
    if material is None:
        material = b.add_material("white", (0.7, 0.7, 0.7))
    b.add_node("floor", b.add_mesh("floor", QUAD, FACES, material=material, **mesh))
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 10.0), translation=(1, 2, 1))
    return b


def _texture(pixels, nearest=True, wrap=(REPEAT, REPEAT), transform=None):
    return Texture(srgb_to_linear(np.asarray(pixels) / 255.0).astype(np.float32), 0, 0, wrap[0], wrap[1],
                   nearest, np.eye(2, 3) if transform is None else transform)


def test_wrap_modes_and_filters():
    row = np.array([[[0, 0, 0], [255, 255, 255], [128, 128, 128], [64, 64, 64]]], np.uint8)  # 4 x 1
    lin = srgb_to_linear(row[0, :, 0] / 255.0)
    u = np.array([-0.9, 0.1, 1.1, 2.6, -0.1])  # texel index floor(4 u): -4, 0, 4, 10, -1 before wrapping
    uv = np.stack([u, np.full_like(u, 0.5)], 1)
    repeat = sample(_texture(row, wrap=(REPEAT, REPEAT)), uv)[:, 0]
    clamp = sample(_texture(row, wrap=(CLAMP_TO_EDGE, REPEAT)), uv)[:, 0]
    mirror = sample(_texture(row, wrap=(MIRRORED_REPEAT, REPEAT)), uv)[:, 0]
    np.testing.assert_allclose(repeat, lin[[0, 0, 0, 2, 3]], rtol=1e-6)
    np.testing.assert_allclose(clamp, lin[[0, 0, 3, 3, 0]], rtol=1e-6)
    np.testing.assert_allclose(mirror, lin[[3, 0, 3, 2, 0]], rtol=1e-6)
    # bilinear: texel centres give the texel, halfway between two centres their mean
    smooth = _texture(row, nearest=False, wrap=(CLAMP_TO_EDGE, CLAMP_TO_EDGE))
    at = sample(smooth, np.array([[0.375, 0.5], [0.5, 0.5], [0.0, 0.5]]))[:, 0]
    np.testing.assert_allclose(at, [lin[1], (lin[1] + lin[2]) / 2, lin[0]], rtol=1e-6)


def test_texture_transform_is_offset_rotation_scale(tmp_path):
    """KHR_texture_transform: uv' = T R S uv (the extension's matrix order)."""
    b = GltfBuilder()
    tex = b.add_texture(np.zeros((2, 2, 3), np.uint8))
    mat = b.add_material("m", (1, 1, 1), base_color_texture=tex,
                         texture_transform={"offset": [0.25, -0.5], "rotation": np.pi / 2, "scale": [2.0, 3.0]})
    b.add_node("floor", b.add_mesh("floor", QUAD, FACES, material=mat, texcoords={0: UV}))
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 1.0), translation=(1, 2, 1))
    b.gltf.extensionsRequired = ["KHR_texture_transform"]  # files may require it: we implement it
    t = read_scene(b.write(tmp_path / "t.glb")).materials[0].base_color_texture
    uv = np.array([1.0, 1.0])
    # scale (2, 3), rotate by pi/2 with the extension's matrix [[c, s], [-s, c]], then offset
    expected = np.array([[0, 1], [-1, 0]]) @ (uv * [2, 3]) + [0.25, -0.5]
    np.testing.assert_allclose(t.transform @ np.append(uv, 1.0), expected, atol=1e-12)
    assert t.has_transform


@pytest.mark.parametrize("where", ["embedded", "external png", "external jpeg"])
def test_images_embedded_or_external(tmp_path, where):
    pixels = np.zeros((64, 64, 3), np.uint8)  # large enough that JPEG's blocks keep the halves flat
    pixels[:, :32] = [200, 40, 40]
    pixels[:, 32:] = [40, 40, 200]
    b = GltfBuilder()
    if where == "embedded":
        tex = b.add_texture(pixels, mag_filter=9728)
        path = tmp_path / "scene.glb"
    else:
        name = "albedo.png" if where == "external png" else "albedo.jpg"
        if name.endswith(".png"):
            (tmp_path / name).write_bytes(encode_png(pixels))
        else:
            import OpenImageIO as oiio

            out = oiio.ImageOutput.create(str(tmp_path / name))
            out.open(str(tmp_path / name), oiio.ImageSpec(64, 64, 3, "uint8"))
            out.write_image(pixels)
            out.close()
        tex = b.add_texture(pixels, uri=name, mag_filter=9728)
        path = tmp_path / "scene.gltf"
    mat = b.add_material("m", (0.5, 1.0, 1.0), base_color_texture=tex)
    b.add_node("floor", b.add_mesh("floor", QUAD, FACES, material=mat, texcoords={0: UV}))
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 1.0), translation=(1, 2, 1))
    state = read_scene(b.write(path)).pose_frame(1)
    surface = SurfaceShading(state, caster_for(state).normals)
    # triangle 1 = corners 0, 3, 2: Embree u weights corner 3 (0, 0, 2), v corner 2 (2, 0, 2), so
    # (u, v) = (0.5, 0.25) is x = 0.5 in the red half (texture u 0.25), (0.1, 0.7) x = 1.4 in the blue
    rgb = surface.base_color(np.array([1, 1]), np.array([0.5, 0.1], np.float32), np.array([0.25, 0.7], np.float32))
    tol = 1e-6 if where != "external jpeg" else 0.06
    np.testing.assert_allclose(rgb[0], [0.5, 1.0, 1.0] * srgb_to_linear(np.array([200, 40, 40]) / 255), atol=tol)
    np.testing.assert_allclose(rgb[1], [0.5, 1.0, 1.0] * srgb_to_linear(np.array([40, 40, 200]) / 255), atol=tol)


def test_texcoord_1_and_vertex_colours(tmp_path):
    """A material sampling TEXCOORD_1 uses that set; COLOR_0 multiplies, interpolated per hit."""
    b = GltfBuilder()
    pixels = np.zeros((1, 2, 3), np.uint8)
    pixels[0, 1] = 255  # left texel black, right texel white
    tex = b.add_texture(pixels, mag_filter=9728)
    mat = b.add_material("m", (1, 1, 1), base_color_texture=tex, texcoord=1)
    colors = np.array([[1, 0, 0], [1, 0, 0], [0, 0, 1], [0, 0, 1]], float)  # red at z = 0, blue at z = 2
    b.add_node("floor", b.add_mesh("floor", QUAD, FACES, material=mat, colors=colors,
                                   texcoords={0: np.zeros((4, 2)), 1: np.full((4, 2), 0.75)}))
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 1.0), translation=(1, 2, 1))
    state = read_scene(b.write(tmp_path / "c.glb")).pose_frame(1)
    surface = SurfaceShading(state, caster_for(state).normals)
    # triangle 0 = corners 0, 2, 1: u weights corner 2 (blue), v corner 1 (red)
    rgb = surface.base_color(np.array([0]), np.array([0.25], np.float32), np.array([0.5], np.float32))
    np.testing.assert_allclose(rgb[0], [0.75, 0.0, 0.25], atol=1e-6)


def test_bad_attributes_and_textures_are_refused(tmp_path):
    b = GltfBuilder()
    b.add_node("floor", b.add_mesh("floor", QUAD, FACES, material=b.add_material("w", (1, 1, 1))))
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 1.0), translation=(1, 2, 1))
    b.gltf.meshes[0].primitives[0].attributes.NORMAL = b.add_accessor(np.ones((3, 3), np.float32))
    with pytest.raises(SceneError, match=r"attributes\.NORMAL: has 3 entries for 4 positions"):
        read_scene(b.write(tmp_path / "n.glb"))

    b = GltfBuilder()
    tex = b.add_texture(np.zeros((2, 2, 3), np.uint8), uri="missing.png")
    mat = b.add_material("m", (1, 1, 1), base_color_texture=tex)
    b.add_node("floor", b.add_mesh("floor", QUAD, FACES, material=mat, texcoords={0: UV}))
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 1.0), translation=(1, 2, 1))
    with pytest.raises(SceneError, match=r"images\[0\]\.uri: missing image file 'missing.png'"):
        read_scene(b.write(tmp_path / "m.gltf"))

    b = GltfBuilder()
    tex = b.add_texture(np.zeros((2, 2, 3), np.uint8), wrap_s=1234)
    mat = b.add_material("m", (1, 1, 1), base_color_texture=tex)
    b.add_node("floor", b.add_mesh("floor", QUAD, FACES, material=mat, texcoords={0: UV}))
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 1.0), translation=(1, 2, 1))
    with pytest.raises(SceneError, match=r"samplers\[0\]\.wrapS: 1234 is not REPEAT"):
        read_scene(b.write(tmp_path / "w.glb"))

    path = tmp_path / "junk.gltf"
    b = GltfBuilder()
    tex = b.add_texture(np.zeros((2, 2, 3), np.uint8), uri="junk.png")
    mat = b.add_material("m", (1, 1, 1), base_color_texture=tex)
    b.add_node("floor", b.add_mesh("floor", QUAD, FACES, material=mat, texcoords={0: UV}))
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 1.0), translation=(1, 2, 1))
    (tmp_path / "junk.png").write_bytes(b"not an image at all")
    with pytest.raises(SceneError, match=r"images\[0\]: cannot decode the image"):
        read_scene(b.write(path))
    result = CliRunner().invoke(main, ["info", str(path)])
    assert result.exit_code != 0 and "images[0]: cannot decode the image" in result.output


def test_info_reports_textures_normals_and_colours(tmp_path):
    b = GltfBuilder()
    tex = b.add_texture(np.zeros((4, 8, 3), np.uint8))
    mat = b.add_material("m", (1, 1, 1), base_color_texture=tex, texture_transform={"offset": [0.5, 0]})
    b.add_node("floor", b.add_mesh("floor", QUAD, FACES, material=mat, normals=np.tile([0, 1, 0], (4, 1)),
                                   colors=np.ones((4, 3))))
    b.add_node("roof", b.add_mesh("roof", QUAD + [0, 1, 0], FACES, material=b.add_material("w", (1, 1, 1))))
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 1.0), translation=(1, 2, 1))
    result = CliRunner().invoke(main, ["info", str(b.write(tmp_path / "i.glb"))])
    assert result.exit_code == 0, result.output
    out = result.output
    assert ("textures   1 image(s) (8x4) as base colour of 1 material(s) (TEXCOORD_0; KHR_texture_transform on 1)"
            in out)
    assert "normals    1 of 2 primitives carry NORMAL (smooth shading); the rest are flat shaded" in out
    assert "colours    1 of 2 primitives carry COLOR_0" in out
    assert "samples TEXCOORD_0, which the primitive lacks" in out  # the floor has no TEXCOORD_0


def _webp(pixels: np.ndarray, path) -> bytes:
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(str(path))
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], 3, "uint8")
    spec.attribute("compression", "lossless")
    out.open(str(path), spec)
    out.write_image(pixels)
    out.close()
    return path.read_bytes()


@pytest.mark.parametrize("fallback", [True, False])
def test_a_webp_image_is_read_in_place_of_its_fallback(tmp_path, fallback):
    """EXT_texture_webp: the texture's WebP image (green) wins over its PNG fallback (red); a file
    that requires the extension has no fallback at all."""
    import base64

    import pygltflib

    green = np.tile(np.array([30, 180, 60], np.uint8), (8, 8, 1))
    b = GltfBuilder()
    tex = b.add_texture(np.tile(np.array([200, 20, 20], np.uint8), (8, 8, 1)))
    data = base64.b64encode(_webp(green, tmp_path / "green.webp")).decode()
    b.gltf.images.append(pygltflib.Image(uri="data:image/webp;base64," + data))
    b.gltf.textures[tex].extensions["EXT_texture_webp"] = {"source": len(b.gltf.images) - 1}
    b.gltf.extensionsUsed.append("EXT_texture_webp")
    if not fallback:
        b.gltf.textures[tex].source = None
        b.gltf.extensionsRequired = ["EXT_texture_webp"]
    mat = b.add_material("m", (1, 1, 1), base_color_texture=tex)
    b.add_node("floor", b.add_mesh("floor", QUAD, FACES, material=mat, texcoords={0: UV}))
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 1.0), translation=(1, 2, 1))
    texture = read_scene(b.write(tmp_path / "webp.glb")).materials[mat].base_color_texture
    np.testing.assert_allclose(texture.mean, srgb_to_linear(np.array([30, 180, 60]) / 255), atol=1e-6)
