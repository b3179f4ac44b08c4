"""Per-process cache of loaded scenes and element meshes, so a worker parses a file once.

Tasks name their scene with a :class:`SceneRef` (its path and hash); a file that changed since the
run began (another hash) is refused, so a worker never traces a different scene than the
coordinator planned.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

from pipeline.errors import SceneError
from pipeline.scene import ElementMesh, Scene

from .environment import load_environment
from .loader import read_scene

_SCENES: dict[tuple, Scene] = {}  # the last _KEEP scenes, oldest first
_KEEP = 2


def load_scene(path: str, scene_hash: str, camera: str | None = None, animation: str | None = None,
               variant: str | None = None, environment: tuple[str, float, float] | None = None) -> Scene:
    """The scene of ``path`` as the run read it (``camera``, ``animation``, ``variant``: read_scene's;
    ``environment``: the (file, strength, rotation) of its environment map), checked against ``scene_hash``,
    which also tells apart the clips, variants and environments a file is rendered with."""
    # One cache entry per (path, hash, camera) however the call spells it: lru_cache keyed on the
    # arguments as passed, so load_scene(p, h) and load_scene(p, h, None) parsed the file twice
    # (0.07-0.15 s each for ROOM, most of it pygltflib's JSON decoding) in every worker
    scene = _SCENES.get((path, scene_hash, camera, animation, variant))
    if scene is None:
        env = None if environment is None else load_environment(*environment)
        scene = read_scene(path, camera=camera, animation=animation, variant=variant, environment=env)
        if scene.scene_hash != scene_hash:
            raise SceneError(f"changed during the run (hash {scene.scene_hash}, expected {scene_hash})", path=path)
        keep_scene(path, camera, scene)
    return scene


def keep_scene(path: str, camera: str | None, scene: Scene) -> None:
    """Cache a scene this process loaded and checked itself under the (path, camera) the tasks ask
    for, and the animation they name (Scene.animation_option): the client's own
    (pipeline/run/render.py), which the report at the end of a render reads again, without parsing
    the file a second time in the serial end of the run."""
    _SCENES[(path, scene.scene_hash, camera, scene.animation_option, scene.variant_option)] = scene
    while len(_SCENES) > _KEEP:
        del _SCENES[next(iter(_SCENES))]


@lru_cache(maxsize=2)
def load_elements(path: str, scene_hash: str, element_size: float, animation: str | None = None,
                  variant: str | None = None, environment: tuple[str, float, float] | None = None) -> ElementMesh:
    """The element mesh of the scene (posed at its first frame, so of the clip that plays)."""
    return ElementMesh.build(load_scene(path, scene_hash, animation=animation, variant=variant,
                                        environment=environment), element_size)


@dataclass(frozen=True)
class SceneRef:
    """A scene as tasks name it: the file, the hash it must still have, the camera (None: the
    file's first), the resolved element size of its element mesh and the animation that plays
    first (None: the file's first, pipeline/scene/loader.py), the material variant (None: none)
    and the environment map's (file, strength, rotation) (None: none)."""

    path: str
    scene_hash: str
    camera: str | None
    element_size: float
    animation: str | None = None
    variant: str | None = None
    environment: tuple[str, float, float] | None = None

    def scene(self) -> Scene:
        return load_scene(self.path, self.scene_hash, self.camera, self.animation, self.variant, self.environment)

    def elements(self) -> ElementMesh:
        return load_elements(self.path, self.scene_hash, self.element_size, self.animation, self.variant,
                             self.environment)
