"""Per-process cache of loaded scenes and element meshes, so a worker parses a file once.

Tasks pass the scene's path and hash; a file that changed since the run began (another hash) is
refused, so a worker never traces a different scene than the coordinator planned.
"""
from __future__ import annotations

from functools import lru_cache

from pipeline.errors import SceneError
from pipeline.scene import ElementMesh, Scene


def load_scene(path: str, scene_hash: str, camera: str | None = None) -> Scene:
    # One cache entry per (path, hash, camera) however the call spells it: lru_cache keys on the
    # arguments as passed, so load_scene(p, h) and load_scene(p, h, None) parsed the file twice
    # (0.07-0.15 s each for ROOM, most of it pygltflib's JSON decoding) in every worker
    return _load_scene(path, scene_hash, camera)


@lru_cache(maxsize=2)
def _load_scene(path: str, scene_hash: str, camera: str | None) -> Scene:
    scene = Scene.load(path, camera=camera)
    if scene.scene_hash != scene_hash:
        raise SceneError(f"changed during the run (hash {scene.scene_hash}, expected {scene_hash})", path=path)
    return scene


@lru_cache(maxsize=2)
def load_elements(path: str, scene_hash: str, element_size: float) -> ElementMesh:
    return ElementMesh.build(load_scene(path, scene_hash), element_size)
