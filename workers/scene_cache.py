"""Per-process cache of loaded scenes and element meshes, so a worker parses a file once.

Tasks pass the scene's path and hash; a file that changed since the run began (another hash) is
refused, so a worker never traces a different scene than the coordinator planned.
"""
from __future__ import annotations

from functools import lru_cache

from pipeline.errors import SceneError
from pipeline.scene import ElementMesh, Scene


@lru_cache(maxsize=2)
def load_scene(path: str, scene_hash: str, camera: str | None = None) -> Scene:
    scene = Scene.load(path, camera=camera)
    if scene.scene_hash != scene_hash:
        raise SceneError(f"changed during the run (hash {scene.scene_hash}, expected {scene_hash})", path=path)
    return scene


@lru_cache(maxsize=2)
def load_elements(path: str, scene_hash: str, element_size: float) -> ElementMesh:
    return ElementMesh.build(load_scene(path, scene_hash), element_size)
