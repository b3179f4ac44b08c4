"""KHR_materials_variants (pipeline/scene/variants.py): a floor whose material is white by default
and red or blue in the file's two variants. The variant's material is the one rendered (the
frame's albedo layer), its scene hash and state keys are its own (no photon of one look is taken
for another's), workers load the same variant through SceneRef, `loom info` lists the variants,
and an unknown variant or a mapping to a missing material is a one-line error."""
from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from pipeline.cli import main
from pipeline.errors import SceneError
from pipeline.frames.images import frame_paths, read_exr
from pipeline.scene import read_scene
from pipeline.scene.scene_cache import SceneRef
from tests.conftest import basic_builder

EXTENSION = "KHR_materials_variants"


def variant_floor(path, *, mapping_material=None):
    """basic_builder's floor and lamp (white, material 0) with variants 'red' (material 1) and 'blue' (2)."""
    b = basic_builder()
    red = b.add_material("red", (0.8, 0.1, 0.1))
    blue = b.add_material("blue", (0.1, 0.1, 0.8))
    b.gltf.extensions[EXTENSION] = {"variants": [{"name": "red"}, {"name": "blue"}]}
    b._use_extension(EXTENSION)
    b.gltf.meshes[0].primitives[0].extensions[EXTENSION] = {"mappings": [
        {"material": red if mapping_material is None else mapping_material, "variants": [0]},
        {"material": blue, "variants": [1]}]}
    b.add_node("cam", camera=b.add_camera("cam", 0.9, 0.05), translation=(1, 3, 1),
               rotation=(-0.7071068, 0, 0, 0.7071068))
    return b.write(path)


def test_a_variant_renders_its_material_and_is_a_scene_of_its_own(tmp_path):
    path = variant_floor(tmp_path / "v.glb")
    plain, red, blue = read_scene(path), read_scene(path, variant="red"), read_scene(path, variant="blue")
    assert [s.materials[s.instances[0].material].name for s in (plain, red, blue)] == ["white", "red", "blue"]
    assert len({plain.scene_hash, red.scene_hash, blue.scene_hash}) == 3
    assert len({s.state_key(1) for s in (plain, red, blue)}) == 3
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["render", str(path), "--out", str(out), "--frames", "1", "--photons", "2000",
                                       "--temporal", "off", "--resolution", "16x12", "--spp", "1", "--variant",
                                       "blue", "--scheduler", "synchronous", "--quiet"])
    assert result.exit_code == 0, result.output
    albedo = read_exr(frame_paths(out, 1)[0])[0]
    seen = np.stack([albedo["albedo.R"], albedo["albedo.G"], albedo["albedo.B"]], axis=-1)
    floor = seen[..., 2] > 0
    assert floor.sum() > 20
    np.testing.assert_allclose(seen[floor], np.tile([0.1, 0.1, 0.8], (floor.sum(), 1)), atol=1e-6)


def test_workers_load_the_variant_the_run_chose(tmp_path):
    path = variant_floor(tmp_path / "v.glb")
    blue = read_scene(path, variant="blue")
    ref = SceneRef(str(path), blue.scene_hash, None, 0.5, None, "blue")
    assert ref.scene().variant_option == "blue"
    with pytest.raises(SceneError, match="changed during the run"):  # the hash tells the variants apart
        SceneRef(str(path), blue.scene_hash, None, 0.5, None, "red").scene()


def test_info_lists_the_variants(tmp_path):
    path = variant_floor(tmp_path / "v.glb")
    info = CliRunner().invoke(main, ["info", str(path), "--variant", "red"])
    assert info.exit_code == 0, info.output
    assert "variants   2: red, blue; rendering 'red' (--variant NAME)" in info.output
    assert EXTENSION not in info.output.replace("variants   ", "")


@pytest.mark.parametrize("make, variant, match", [
    (lambda p: variant_floor(p), "green", r"--variant: no variant 'green': the file's variants are 'red', 'blue'"),
    (lambda p: variant_floor(p, mapping_material=9), "red",
     r"meshes\[0\].primitives\[0\].extensions.KHR_materials_variants.mappings\[0\].material: refers to a missing "
     r"material 9"),
    (lambda p: basic_builder().write(p), "red", r"no variant 'red': the file's variants are none"),
])
def test_bad_variants_are_one_line_errors(tmp_path, make, variant, match):
    path = make(tmp_path / "v.glb")
    with pytest.raises(SceneError, match=match) as err:
        read_scene(path, variant=variant)
    assert "\n" not in str(err.value)
