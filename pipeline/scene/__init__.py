"""Scenes: glTF 2.0 loading, animation, lights, materials, camera, element mesh, built-in scenes."""
from __future__ import annotations

from .elements import ElementMesh
from .loader import read_scene
from .nodes import MeshInstance
from .scene import FrameState, Scene
from .timeline import Timeline, parse_frame_range

__all__ = ["ElementMesh", "FrameState", "MeshInstance", "Scene", "read_scene", "Timeline", "parse_frame_range"]
