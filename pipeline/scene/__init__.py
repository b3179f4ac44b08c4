"""Scenes: glTF 2.0 loading, animation, lights, materials, camera, element mesh, built-in scenes."""
from __future__ import annotations

from .elements import ElementMesh
from .scene import FrameState, MeshInstance, Scene
from .timeline import Timeline, parse_frame_range

__all__ = ["ElementMesh", "FrameState", "MeshInstance", "Scene", "Timeline", "parse_frame_range"]
