"""KHR_animation_pointer beyond colours and intensities (pipeline/scene/pointers.py): a material's
metallic and roughness factors (its kind changes with them), a texture transform that scrolls,
a spot light's cones and a light's range, pointers that change nothing in a ray-traced picture, and
files that require the extension: loaded when every pointer is animated, refused on one line
naming the pointers otherwise."""
from __future__ import annotations

import numpy as np
import pytest

from pipeline.errors import SceneError
from pipeline.scene import read_scene
from tests.conftest import basic_builder
from tests.scene.test_animation import IOR, LAMP


def _require(b):
    b.gltf.extensionsRequired = ["KHR_animation_pointer"]


def test_metallic_and_roughness_make_a_floor_a_mirror(tmp_path):
    b = basic_builder()
    b.gltf.materials[0].pbrMetallicRoughness.metallicFactor = 1.0
    b.add_pointer_animation("polish", "/materials/0/pbrMetallicRoughness/roughnessFactor", [0, 1], [1.0, 0.1])
    scene = read_scene(b.write(tmp_path / "polish.glb"))
    assert scene.materials[0].kind == "diffuse" and scene.has_specular  # a mirror at some instant
    kinds = [scene.pose(t).materials[0].kind for t in (0.0, 0.5, 1.0)]
    assert kinds == ["diffuse", "glossy", "mirror"]
    assert scene.pose(0.5).materials[0].roughness == pytest.approx(0.55)
    assert len({scene.pose(t).state_key for t in (0.0, 0.5, 1.0)}) == 3


def test_a_texture_scrolls_through_its_transform(tmp_path):
    b = basic_builder()
    tex = b.add_texture(np.arange(48, dtype=np.uint8).reshape(4, 4, 3))
    scrolled = b.add_material("scrolled", (1, 1, 1), base_color_texture=tex,
                              texture_transform={"rotation": 0.5, "scale": [2.0, 2.0]})
    b.gltf.meshes[0].primitives[0].material = scrolled
    pointer = f"/materials/{scrolled}/pbrMetallicRoughness/baseColorTexture/extensions/KHR_texture_transform/offset"
    b.add_pointer_animation("scroll", pointer, [0, 1], [[0.0, 0.0], [-1.0, 0.5]])
    scene = read_scene(b.write(tmp_path / "scroll.glb"))
    rest = scene.materials[scrolled].base_color_texture.transform
    half = scene.pose(0.5).materials[scrolled].base_color_texture.transform
    np.testing.assert_allclose(half[:, :2], rest[:, :2])  # rotation and scale kept from the file
    np.testing.assert_allclose(half[:, 2], [-0.5, 0.25])  # offset is the translation, negative allowed
    assert scene.pose(0.0).state_key != scene.pose(0.5).state_key
    assert not any("KHR_animation_pointer" in w for w in scene.warnings)


def test_a_spot_widens_and_a_lamp_reaches_further(tmp_path):
    b = basic_builder(light=False)
    spot = b.add_spot_light("spot", (1, 1, 1), 10.0, inner_cone_angle=0.1, outer_cone_angle=0.3)
    b.add_node("spot", light=spot, translation=(1, 2, 1), rotation=(-0.7071068, 0, 0, 0.7071068))
    b.add_pointer_animation("widen", f"/extensions/KHR_lights_punctual/lights/{spot}/spot/outerConeAngle",
                            [0, 1], [0.3, 0.6])
    b.add_pointer_animation("widen", f"/extensions/KHR_lights_punctual/lights/{spot}/spot/innerConeAngle",
                            [0, 1], [0.1, 0.7])  # beyond the outer cone at the end: kept inside it
    scene = read_scene(b.write(tmp_path / "spot.glb"))
    narrow, wide = (scene.pose(t).lights[0] for t in (0.0, 1.0))
    assert (narrow.definition.inner_cone, narrow.definition.outer_cone) == pytest.approx((0.1, 0.3))
    assert wide.definition.outer_cone == pytest.approx(0.6) and wide.definition.inner_cone < 0.6
    assert wide.power(1.0)[0] > 3 * narrow.power(1.0)[0]  # about the cone's solid angle
    assert scene.pose(0.0).state_key != scene.pose(1.0).state_key


def test_pointers_that_change_nothing_here_are_read_quietly(tmp_path):
    b = basic_builder()
    cam = b.add_camera("cam", 0.8, 0.1, zfar=50.0)
    b.add_node("cam", camera=cam, translation=(0, 1, 5))
    b.add_pointer_animation("clip", f"/cameras/{cam}/perspective/znear", [0, 1], [0.1, 0.5])
    b.add_pointer_animation("clip", f"/cameras/{cam}/perspective/zfar", [0, 1], [50.0, 20.0])
    scene = read_scene(b.write(tmp_path / "clip.glb"))
    assert not scene.warnings and not scene.has_animation


def test_a_file_requiring_the_extension_loads_when_every_pointer_is_animated(tmp_path):
    b = basic_builder()
    b.add_pointer_animation("lamp", LAMP + "/intensity", [0, 1], [10.0, 40.0])
    _require(b)
    assert read_scene(b.write(tmp_path / "required.glb")).light_channels
    b.add_pointer_animation("glass", IOR, [0, 1], [1.5, 1.3])
    with pytest.raises(SceneError, match=r"extensionsRequired: requires KHR_animation_pointer for "
                                         r"/materials/\{i\}/extensions/KHR_materials_ior/ior, which photonloom does "
                                         r"not animate \(it animates node translation") as err:
        read_scene(b.write(tmp_path / "refused.glb"))
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("pointer, values, match", [
    (LAMP + "/range", [1.0, 2.0], "light 0 defines no range to animate"),
    (LAMP + "/spot/outerConeAngle", [0.3, 0.6], "light 0 is not a spot light"),
    ("/materials/0/emissiveTexture/extensions/KHR_texture_transform/scale", [[1, 1], [2, 2]],
     "material 0 has no emissiveTexture to transform"),
])
def test_a_pointer_to_what_the_file_lacks_is_a_one_line_error(tmp_path, pointer, values, match):
    b = basic_builder()
    b.add_pointer_animation("bad", pointer, [0, 1], values)
    with pytest.raises(SceneError, match=r"animations\[0\].channels\[0\].target.extensions.KHR_animation_pointer"
                                         r".pointer: .*" + match):
        read_scene(b.write(tmp_path / "bad.glb"))


def test_a_light_range_keeps_positive(tmp_path):
    b = basic_builder(light=False)
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 10.0, range=4.0), translation=(1, 2, 1))
    b.add_pointer_animation("reach", LAMP + "/range", [0, 1], [4.0, 1.0])
    scene = read_scene(b.write(tmp_path / "range.glb"))
    assert scene.pose(0.5).lights[0].definition.range == pytest.approx(2.5)
    b.add_pointer_animation("bad", LAMP + "/range", [0, 1], [4.0, -1.0])
    with pytest.raises(SceneError, match=r"light range keys must not be negative"):
        read_scene(b.write(tmp_path / "bad.glb"))
