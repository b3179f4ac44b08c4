"""Built-in scenes through the real loader: element counts, state keys, what each scene needs."""
from __future__ import annotations

import pytest
from click.testing import CliRunner

from pipeline.cli import main
from pipeline.scene import ElementMesh, Scene, read_scene
from pipeline.scene.builtin import atrium, write_builtin

TARGET_ELEMENTS = {"room": 5_300, "atrium": 45_000}
PAPER_SIZE = {"room": None, "atrium": atrium.PAPER_ELEMENT_SIZE}  # None: the scene's own element size


@pytest.fixture(scope="module")
def builtin(tmp_path_factory):
    out = tmp_path_factory.mktemp("builtin")
    cache = {}

    def load(name: str) -> Scene:
        if name not in cache:
            cache[name] = read_scene(write_builtin(name, out / f"{name}.glb"))
        return cache[name]

    return load


@pytest.mark.parametrize("name", sorted(TARGET_ELEMENTS))
def test_element_counts_match_the_paper(builtin, name):
    mesh = ElementMesh.build(builtin(name), PAPER_SIZE[name])
    assert abs(mesh.n_elements / TARGET_ELEMENTS[name] - 1) <= 0.15


def test_atrium_own_elements_are_one_and_a_half_times_the_papers(builtin):
    """The coarsest size `loom bench elements` finds within d_thr of the paper's mesh (docs/04-photons.md §8)."""
    own = ElementMesh.build(builtin("atrium"))
    assert own.element_size == 1.5 * atrium.PAPER_ELEMENT_SIZE
    assert own.n_elements < 0.6 * ElementMesh.build(builtin("atrium"), atrium.PAPER_ELEMENT_SIZE).n_elements


def test_room_is_three_segments_with_moving_lit_objects(builtin):
    room = builtin("room")
    assert room.timeline.frames >= 135 and room.timeline.fps == 30
    assert room.has_moving_geometry and room.has_specular
    kinds = {d.kind for d in room.light_defs}
    assert "spot" in kinds
    assert len(room.animated_nodes) >= 2


def test_atrium_has_sun_and_lamps(builtin):
    atrium = builtin("atrium")
    kinds = [d.kind for d in atrium.light_defs]
    assert "directional" in kinds and len(kinds) >= 2
    assert atrium.timeline.frames >= 290
    assert len(atrium.animated_nodes) >= 3


def test_static_scene_state_keys_are_equal_for_camera_only_motion(builtin):
    static = builtin("static")
    keys = static.frame_state_keys
    assert len(set(keys)) == 1
    assert static.has_camera_motion and not static.has_moving_geometry
    c1, c2 = static.pose_frame(1).camera, static.pose_frame(static.timeline.last).camera
    assert abs(c1.position - c2.position).max() > 0.1


@pytest.mark.parametrize("name", ["room", "cornell"])
def test_state_keys_differ_where_objects_move(builtin, name):
    scene = builtin(name)
    keys = scene.frame_state_keys
    assert keys[0] != keys[len(keys) // 2] != keys[-1]


def test_cornell_is_small_with_an_area_light(builtin):
    cornell = builtin("cornell")
    assert ElementMesh.build(cornell).n_elements < 2_000
    assert cornell.has_area_lights and len(cornell.pose_frame(1).emissive_triangles) >= 2


def test_loom_scene_and_info_cli(tmp_path):
    runner = CliRunner()
    out = tmp_path / "room.glb"
    assert runner.invoke(main, ["scene", "room", "-o", str(out)]).exit_code == 0
    result = runner.invoke(main, ["info", str(out)])
    assert result.exit_code == 0, result.output
    text = result.output
    for word in ("frames     135 at 30 fps", "elements", "spot", "specular", "moving geometry", "cameras"):
        assert word in text
    bad = runner.invoke(main, ["scene", "nosuch", "-o", str(tmp_path / "x.glb")])
    assert bad.exit_code == 2 and "unknown built-in scene" in bad.output
