"""Shared fixtures: a fixed-seed RNG and small glTF files written by the real builder."""
from __future__ import annotations

import numpy as np
import pytest

from pipeline.scene.builtin.gltf_builder import GltfBuilder

QUAD = np.array([[0, 0, 0], [2, 0, 0], [2, 0, 2], [0, 0, 2]], dtype=float)
QUAD_FACES = np.array([0, 2, 1, 0, 3, 2])


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def sun_and_camera_above(b: GltfBuilder, at: tuple = (1, 3, 1)) -> None:
    """A sun straight down (3 W/m^2 white) and a camera at ``at`` looking straight down (yfov 0.9)."""
    down = (-0.7071068, 0, 0, 0.7071068)  # -Z turned to -Y
    b.add_node("sun", light=b.add_directional_light("sun", (1, 1, 1), 3.0), rotation=down)
    b.add_node("cam", camera=b.add_camera("cam", 0.9, 0.05), translation=at, rotation=down)


def basic_builder(light: bool = True) -> GltfBuilder:
    """A 2 x 2 floor at y = 0 lit by a point light 2 units above its centre."""
    b = GltfBuilder()
    white = b.add_material("white", (0.7, 0.7, 0.7))
    b.add_node("floor", b.add_mesh("floor", QUAD, QUAD_FACES, material=white))
    if light:
        b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 10.0), translation=(1, 2, 1))
    return b


@pytest.fixture
def basic_scene_file(tmp_path):
    path = tmp_path / "basic.glb"
    basic_builder().write(path)
    return path
