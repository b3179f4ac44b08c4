"""KHR_texture_basisu (pipeline/scene/textures.py): KTX2 images with Basis Universal payloads
(tests/scene/ktx2/, ETC1S and UASTC) give the texels of the same image as a PNG, within the codecs'
error (ETC1S: a few 8-bit levels; UASTC: exact on flat quadrants), with their alpha; a file that
requires the extension and has no fallback renders; a broken KTX2 and one whose header claims
16384 x 16384 pixels from 331 bytes are one-line errors before anything is decoded."""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pygltflib
import pytest
from click.testing import CliRunner

from pipeline.cli import main
from pipeline.errors import SceneError
from pipeline.scene import read_scene
from pipeline.scene.textures import srgb_to_linear
from tests.conftest import QUAD, QUAD_FACES, basic_builder

KTX2 = Path(__file__).parent / "ktx2"
QUADRANTS = np.array([[(200, 30, 30), (30, 200, 30)], [(30, 30, 200), (240, 240, 240)]], float) / 255


def textured(path: Path, ktx2: bytes, *, fallback: bool = False) -> Path:
    """basic_builder's floor with a base-colour texture whose image is ``ktx2`` (KHR_texture_basisu,
    required), and a PNG fallback of the same quadrants where ``fallback``."""
    b = basic_builder()
    png = np.kron(np.round(QUADRANTS * 255), np.ones((4, 4, 1))).astype(np.uint8)
    tex = b.add_texture(png)  # the builder's PNG: the fallback's image
    b._pad_blob()
    start = len(b._blob)
    b._blob += ktx2
    b.gltf.bufferViews.append(pygltflib.BufferView(buffer=0, byteOffset=start, byteLength=len(ktx2)))
    b.gltf.images.append(pygltflib.Image(bufferView=len(b.gltf.bufferViews) - 1, mimeType="image/ktx2"))
    texture = b.gltf.textures[tex]
    texture.extensions = {"KHR_texture_basisu": {"source": len(b.gltf.images) - 1}}
    if not fallback:
        texture.source = None
    b._use_extension("KHR_texture_basisu")
    b.gltf.extensionsRequired = sorted(set(b.gltf.extensionsRequired or []) | {"KHR_texture_basisu"})
    uv = np.c_[QUAD[:, 0] / 2, QUAD[:, 2] / 2]
    mat = b.add_material("tiles", (1.0, 1.0, 1.0), base_color_texture=tex)
    b.add_node("tiles", b.add_mesh("tiles", QUAD, QUAD_FACES, material=mat, texcoords={0: uv}),
               translation=(0, 0.5, 0))
    return b.write(path)


@pytest.mark.parametrize("name, tolerance", [("quadrants_etc1s.ktx2", 4 / 255), ("quadrants_alpha_uastc.ktx2", 0.0)])
def test_a_ktx2_image_gives_the_texels_of_the_same_png(tmp_path, name, tolerance):
    scene = read_scene(textured(tmp_path / "k.glb", (KTX2 / name).read_bytes()))
    texture = scene.materials[1].base_color_texture
    assert texture.image.shape == (8, 8, 3)
    want = np.kron(QUADRANTS, np.ones((4, 4, 1)))  # the sRGB-encoded values
    assert np.abs(texture.image - srgb_to_linear(want)).max() < 0.02  # linear, as a PNG's texels
    encoded = np.where(texture.image <= 0.0031308, texture.image * 12.92, 1.055 * texture.image ** (1 / 2.4) - 0.055)
    assert np.abs(encoded - want).max() <= tolerance + 1e-4
    if "alpha" in name:
        np.testing.assert_allclose(texture.alpha[4:, 4:], 128 / 255, atol=1e-6)
        assert (texture.alpha[:4] == 1).all()
    else:
        assert texture.alpha is None


def test_a_file_requiring_the_extension_renders(tmp_path):
    path = textured(tmp_path / "k.glb", (KTX2 / "quadrants_etc1s.ktx2").read_bytes())
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["render", str(path), "--out", str(out), "--frames", "1", "--photons", "2000",
                                       "--temporal", "off", "--resolution", "32x24", "--spp", "1",
                                       "--scheduler", "synchronous", "--quiet"])
    assert result.exit_code == 0, result.output
    info = CliRunner().invoke(main, ["info", str(path)])
    assert "KHR_texture_basisu" not in info.output and "8x8" in info.output


@pytest.mark.parametrize("damage, match", [
    (lambda d: d[:200], r"images\[1\]: cannot transcode the KTX2 image"),
    (lambda d: d[:20] + struct.pack("<II", 16384, 16384) + d[28:],
     r"images\[1\]: 16384 x 16384 pixels is more than the 134,217,728 an image may have"),
])
def test_a_broken_or_boastful_ktx2_is_a_one_line_error(tmp_path, damage, match):
    data = (KTX2 / "quadrants_etc1s.ktx2").read_bytes()
    with pytest.raises(SceneError, match=match) as err:
        read_scene(textured(tmp_path / "bad.glb", damage(data)))
    assert "\n" not in str(err.value)
