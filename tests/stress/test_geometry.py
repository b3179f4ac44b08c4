"""Awkward geometry: sliver and near-degenerate triangles, elements no photon
hits, and a triangle 1e6 units across.

The room of tests/stress/scenes.lit_room gets, on its floor, a sliver (3 units long, 1e-3 wide) and
a near-degenerate triangle (2 units long, 1e-6 wide: about 1e-12 of its bounding box squared, above
the loader's zero-area cut); a sealed box on the floor with a triangle inside it that no photon can
reach; and, outside the closed room, a ground triangle 1e6 units across that no photon reaches
either (its 1e12 elements of element_size 0.5 would be refused: it is split MAX_SPLIT x MAX_SPLIT,
pipeline/scene/elements.py). Nothing may turn into NaN or Inf, unlit elements stay exactly 0 and
the room's light must not change beyond photon noise.
"""
from __future__ import annotations

import logging

import numpy as np
import pytest

from pipeline.frames.images import EXR_CHANNELS, frame_paths, read_exr
from pipeline.frames.settings import RenderSettings
from pipeline.run.render import RenderRequest, render
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.elements import MAX_SPLIT
from pipeline.store.illumination import IlluminationMaps
from tests.stress.scenes import QUAD_FACES, inward_quads, lit_room

N = 40_000


def _slivers(b):
    grey = b.add_material("sliver", (0.8, 0.8, 0.8))
    tris = np.array([[-1.5, -1.99, 1.0], [1.5, -1.99, 1.0], [0.0, -1.99, 1.001],
                     [-1.0, -1.98, -1.2], [1.0, -1.98, -1.2], [0.2, -1.98, -1.2 + 1e-6]])
    b.add_node("slivers", b.add_mesh("slivers", tris, None, material=grey))
    sealed = [q * 0.2 + [-1.0, -1.8, 0.0] for q in inward_quads(1.0)]
    inside = np.array([[-1.1, -1.9, -0.05], [-0.9, -1.9, -0.05], [-1.0, -1.7, 0.05]])
    b.add_node("sealed", b.add_mesh("sealed", np.concatenate(sealed + [inside]),
                                    np.concatenate([QUAD_FACES + 4 * i for i in range(6)] + [np.arange(24, 27)]),
                                    material=grey))


def _ground(b):
    _slivers(b)
    ground = b.add_material("ground", (0.5, 0.5, 0.5))
    tri = np.array([[-5e5, -3.0, -3e5], [5e5, -3.0, -3e5], [0.0, -3.0, 5e5]])
    b.add_node("ground", b.add_mesh("ground", tri, None, material=ground))


def _run(tmp, name, extra):
    path = lit_room(tmp / f"{name}.glb", extra=extra, frames=2)
    out = tmp / name
    render(RenderRequest(scene_path=path, frames="1-2", out_dir=out, n_photons=N, temporal="off",
                         settings=RenderSettings(width=40, height=30, spp=2)), scheduler="synchronous")
    scene = read_scene(path)
    elements = ElementMesh.build(scene)
    state = scene.pose_frame(1)
    maps = IlluminationMaps.open(str(out / "photons.zarr"))
    return dict(path=path, elements=elements, positions=elements.vertex_positions(state),
                areas=elements.vertex_areas(state), indirect=[maps.read(i, "indirect") for i in range(2)],
                direct=[maps.read(i, "direct") for i in range(2)],
                frames=[read_exr(frame_paths(out, f)[0])[0] for f in (1, 2)])


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("geometry")
    return {name: _run(tmp, name, extra) for name, extra in (("plain", None), ("slivers", _slivers))}


@pytest.fixture(scope="module")
def ground(tmp_path_factory):
    """The room on a 1e6-unit ground: 262,144 more elements (about 20 s on 2 cores, slow)."""
    return _run(tmp_path_factory.mktemp("ground"), "ground", _ground)


def _room_mean(run):
    """Area-weighted mean indirect irradiance over the room's six walls (|coordinate| = 2)."""
    walls = np.isclose(np.abs(run["positions"]).max(axis=1), 2.0)
    a = run["areas"][walls]
    return np.mean([(m[walls] * a[:, None]).sum(axis=0) / a.sum() for m in run["indirect"]], axis=0)


def _assert_finite(run):
    for maps in (run["indirect"], run["direct"]):
        assert all(np.isfinite(m).all() and (m >= 0).all() for m in maps)
    for frame in run["frames"]:
        assert all(np.isfinite(frame[c]).all() for c in EXR_CHANNELS)


def test_slivers_turn_into_no_nan_or_inf(runs):
    _assert_finite(runs["slivers"])
    sliver = np.abs(runs["slivers"]["positions"][:, 1] + 1.985) < 0.006  # the two slivers' vertices
    assert sliver.sum() >= 6 and (runs["slivers"]["areas"][sliver] < 1e-3).all()


def test_unlit_elements_stay_zero(runs):
    run = runs["slivers"]
    sealed_inside = (np.abs(run["positions"] - [-1.0, -1.8, 0.0]) < 0.15).all(axis=1)
    assert sealed_inside.sum() >= 3
    for m in run["indirect"] + run["direct"]:
        assert (m[sealed_inside] == 0).all()


def test_slivers_leave_the_room_light_unchanged(runs):
    # 40,000 photons a frame, 2 frames: about 0.5 % noise on the walls' mean; the slivers and the
    # sealed box shade a little of the floor
    np.testing.assert_allclose(_room_mean(runs["slivers"]), _room_mean(runs["plain"]), rtol=0.03)


def test_huge_triangle_is_split_coarser(tmp_path, caplog):
    path = lit_room(tmp_path / "ground.glb", extra=_ground)
    with caplog.at_level(logging.WARNING, logger="pipeline.scene.elements"):
        elements = ElementMesh.build(read_scene(path))
    assert np.diff(elements.triangle_offset).max() == MAX_SPLIT ** 2
    assert f"split {MAX_SPLIT} x {MAX_SPLIT}" in caplog.text


@pytest.mark.slow
def test_huge_ground_turns_into_no_nan_or_inf(ground):
    _assert_finite(ground)


@pytest.mark.slow
def test_huge_ground_leaves_the_room_light_unchanged(runs, ground):
    assert (ground["indirect"][0][ground["positions"][:, 1] < -2.5] == 0).all()  # no photon leaves the room
    np.testing.assert_allclose(_room_mean(ground), _room_mean(runs["plain"]), rtol=0.03)
