"""Files without a camera or a light: the auto camera, the default sun and sky, and what
``loom info`` says about them and about what it ignores."""
from __future__ import annotations

import logging
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from pipeline.cli import main
from pipeline.errors import SceneError
from pipeline.scene import read_scene
from pipeline.scene.default_camera import YFOV_DEG, framing_camera
from tests.conftest import basic_builder
from tests.frames.scenes import plane_scene
from tests.scene.unlit_scenes import box_in_box


def _camera_coordinates(camera, points):
    p = np.c_[points, np.ones(len(points))] @ camera.world_to_camera.T
    return p[:, :3]


def test_the_auto_camera_sees_every_vertex_of_every_frame(tmp_path):
    scene = read_scene(box_in_box(tmp_path / "bib.glb"))
    assert scene.camera_node is None and scene.camera_name == "auto"
    cam = scene.framing.camera
    tan_half = np.tan(np.radians(YFOV_DEG) / 2)
    widest = 0.0
    for frame in scene.timeline.all_frames():
        state = scene.pose_frame(frame)
        assert state.camera is cam
        c = _camera_coordinates(cam, state.vertices.astype(np.float64))
        assert np.all(c[:, 2] < 0)  # in front (the camera looks down its -Z)
        ratio = np.maximum(np.abs(c[:, 0]), np.abs(c[:, 1])) / -c[:, 2]
        assert ratio.max() <= tan_half
        widest = max(widest, ratio.max())
    assert widest > 0.8 * tan_half  # framed, not lost in the distance
    # the stated direction: from azimuth 30 degrees (towards +x from +z), 20 degrees up
    back = cam.to_world[:3, 2]
    np.testing.assert_allclose(back, [np.sin(np.radians(30)) * np.cos(np.radians(20)), np.sin(np.radians(20)),
                                      np.cos(np.radians(30)) * np.cos(np.radians(20))], atol=1e-12)
    np.testing.assert_allclose(cam.up @ [0, 1, 0] > 0, True)


def test_framing_follows_the_moving_box():
    """Bounds that grow along +x move the target along +x and the camera back."""
    near = framing_camera(np.array([-1.0, 0, -1]), np.array([1.0, 1, 1]))
    far = framing_camera(np.array([-1.0, 0, -1]), np.array([5.0, 1, 1]))
    assert far.position[0] > near.position[0]
    assert np.linalg.norm(far.position - [2, 0.5, 0]) > np.linalg.norm(near.position - [0, 0.5, 0])


def test_camera_auto_replaces_the_files_camera(tmp_path):
    path = plane_scene(tmp_path / "plane.glb")
    assert read_scene(path).camera_name == "cam"
    scene = read_scene(path, camera="auto")
    assert scene.camera_name == "auto" and scene.framing is not None
    assert not any("camera" in n for n in scene.notices)  # asked for: no notice
    with pytest.raises(SceneError, match="cameras: auto, cam"):
        read_scene(path, camera="nope")


def test_a_file_without_camera_or_light_gets_the_defaults_with_one_notice_each(tmp_path, caplog):
    path = box_in_box(tmp_path / "bib.glb")
    with caplog.at_level(logging.INFO, logger="pipeline.scene.notices"):
        scene = read_scene(path)
        read_scene(path)  # once per file and process
    notices = [r.getMessage() for r in caplog.records if r.name == "pipeline.scene.notices"]
    assert len(notices) == 2 and all("\n" not in n and str(path) in n for n in notices)
    assert "no camera" in notices[0] and "azimuth 30 deg, elevation 20 deg, yfov 40 deg" in notices[0]
    assert "no light" in notices[1] and "--light none" in notices[1]
    state = scene.pose_frame(1)
    assert [li.kind for li in state.lights] == ["directional"] and state.sky is scene.sky
    assert state.lights[0].direction[1] < 0  # the sun shines down


def test_light_none_keeps_the_error(tmp_path):
    path = box_in_box(tmp_path / "bib.glb")
    with pytest.raises(SceneError, match="has no light") as err:
        read_scene(path, light="none")
    assert str(path) in str(err.value) and "\n" not in str(err.value)
    result = CliRunner().invoke(main, ["info", str(path), "--light", "none"])
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert result.exit_code == 2 and len(lines) == 1 and lines[0].startswith("loom: error: ")


def test_a_file_with_light_and_camera_gets_no_defaults(tmp_path, basic_scene_file):
    scene = read_scene(basic_scene_file, light="none")
    assert scene.sky is None and scene.default_lights == ()
    assert [li.kind for li in scene.pose_frame(1).lights] == ["point"]
    lit = read_scene(plane_scene(tmp_path / "plane.glb"))
    assert lit.notices == [] and lit.framing is None and lit.pose_frame(1).sky is None


def test_loom_info_says_which_camera_and_lights(tmp_path):
    path = box_in_box(tmp_path / "bib.glb")
    out = CliRunner().invoke(main, ["info", str(path)]).output
    cameras = next(line for line in out.splitlines() if line.startswith("cameras"))
    assert "rendering with the auto camera from azimuth 30 deg, elevation 20 deg, yfov 40 deg" in cameras
    lights = next(line for line in out.splitlines() if line.startswith("lights"))
    assert "the file has none, rendering with the default sun" in lights and "uniform sky" in lights
    named = CliRunner().invoke(main, ["info", str(plane_scene(tmp_path / "plane.glb"))]).output
    assert "rendering with cam" in named and "default sun" not in named


def test_loom_info_lists_what_it_ignores_and_why(tmp_path):
    b = basic_builder()
    g = b.gltf
    g.nodes[0].skin = b.add_skin([0])  # the floor is its own joint
    b.bind_skin(0, 0, np.zeros((4, 4), int), np.tile([1.0, 0, 0, 0], (4, 1)))
    b.add_morph_targets(0, 0, [np.zeros((4, 3))])
    g.extensionsUsed.append("KHR_materials_clearcoat")
    g.materials[0].extensions["KHR_materials_clearcoat"] = {"clearcoatFactor": 1.0}
    g.extensionsUsed.append("EXT_lights_image_based")
    path = b.write(tmp_path / "extras.glb")
    out = CliRunner().invoke(main, ["info", str(path)]).output
    ignored = [line for line in out.splitlines() if line.startswith("ignored")]
    assert not any("skin" in line or "morph" in line for line in ignored)  # both are rendered
    assert [line for line in out.splitlines() if line.startswith("deforms")] == [
        "deforms    1 of 1 primitives posed per vertex: floor/floor[0]: skin 0 (1 joints, 0 animated, up to 4 "
        "influences), 1 morph target(s), weights fixed"]
    assert any("KHR_materials_clearcoat: not implemented, the core metallic-roughness factors" in line
               for line in ignored)
    assert any("EXT_lights_image_based: not implemented, the core glTF data is used" in line for line in ignored)
    assert not any("KHR_lights_punctual" in line for line in ignored)  # implemented
    clean = CliRunner().invoke(main, ["info", str(plane_scene(tmp_path / "plane.glb"))]).output
    assert "ignored" not in clean


@pytest.mark.parametrize("command", ["shoot", "render"])
def test_light_none_refuses_before_writing_anything(tmp_path, command):
    path = box_in_box(tmp_path / "bib.glb")
    target = tmp_path / "out"
    args = (["--store", str(target)] if command == "shoot" else ["--out", str(target)])
    result = CliRunner().invoke(main, [command, str(path), *args, "--light", "none", "--scheduler", "synchronous"])
    assert result.exit_code == 2 and "has no light" in result.output
    assert not target.exists()


def test_quiet_renders_announce_no_defaults(tmp_path):
    # The loader's notices print through logging to stderr: a real process shows what a user sees
    path = box_in_box(tmp_path / "bib.glb")
    loom = [sys.executable, "-m", "pipeline"]
    common = ["--frames", "1", "--resolution", "16x12", "--spp", "1", "--scheduler", "synchronous"]
    quiet = subprocess.run([*loom, "render", str(path), "--out", str(tmp_path / "q"), *common, "--quiet"],
                           capture_output=True, text=True)
    loud = subprocess.run([*loom, "render", str(path), "--out", str(tmp_path / "l"), *common],
                          capture_output=True, text=True)
    assert quiet.returncode == 0 and loud.returncode == 0, quiet.stderr + loud.stderr
    assert "no camera" in loud.stderr and "INFO" not in quiet.stderr
    assert "rendered 1 frames" in quiet.stdout
