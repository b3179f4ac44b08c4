"""pipeline/scene/scene_cache.py: one parse per (file, hash, camera) in a process, a changed file refused."""
from __future__ import annotations

import pytest

from pipeline.errors import SceneError
from pipeline.scene import read_scene
from pipeline.scene.scene_cache import keep_scene, load_elements, load_scene


def test_a_scene_is_parsed_once_however_the_camera_argument_is_spelled(basic_scene_file):
    path, digest = str(basic_scene_file), read_scene(basic_scene_file).scene_hash
    scene = load_scene(path, digest)
    assert load_scene(path, digest, None) is scene  # the tasks' two spellings share one entry
    assert load_elements(path, digest, 0.5).n_elements > 0
    assert load_scene(path, digest) is scene  # building elements reused it too


def test_a_file_that_changed_since_the_run_began_is_refused(basic_scene_file):
    with pytest.raises(SceneError, match="changed during the run"):
        load_scene(str(basic_scene_file), "0" * 16)


def test_a_scene_the_client_loaded_is_not_parsed_again(basic_scene_file):
    scene = read_scene(basic_scene_file)
    keep_scene(str(basic_scene_file), "auto", scene)
    assert load_scene(str(basic_scene_file), scene.scene_hash, "auto") is scene  # a parse makes a new one
