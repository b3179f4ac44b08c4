"""Relighting recorded camera paths (pipeline/frames/map_hits.py) against rendering them again:
the indirect layer of any map, to the bit, through glossy and metal bounces, misses and chunks."""
from __future__ import annotations

import numpy as np
import pytest

from pipeline.frames.camera_paths import CameraPaths, render_frame
from pipeline.scene import ElementMesh, read_scene


@pytest.mark.parametrize("spp, chunk_rays", [(1, 1 << 14), (4, 1 << 14), (4, 1000)])
def test_relit_paths_have_the_bits_of_a_render_with_each_map(tmp_path, spp, chunk_rays):
    from pipeline.scene.builtin import write_builtin

    scene = read_scene(write_builtin("room", tmp_path / "room.glb"))  # diffuse, glossy and metal surfaces
    state, elements = scene.pose_frame(1), ElementMesh.build(scene)
    rng = np.random.default_rng(11)
    maps = [rng.uniform(0.0, 2.0, (elements.n_vertices, 3)) for _ in range(3)]
    paths = CameraPaths(40, 30, spp, seed=3, frame=1)
    recorded = render_frame(state, elements, maps[0], paths, chunk_rays=chunk_rays, record_hits=True)
    hits = recorded.map_hits
    assert len(np.unique(hits.sample)) == len(hits.sample)  # one map reading a sample at most
    assert (hits.throughput != 1).any()  # some hits come after a glossy or metal bounce
    for m in maps:
        alone = render_frame(state, elements, m, paths)
        relit = hits.indirect(elements, m)
        assert np.array_equal(relit, alone.indirect)
        assert np.array_equal(recorded.direct + relit, alone.beauty)
    assert not np.array_equal(hits.indirect(elements, maps[1]), hits.indirect(elements, maps[2]))


def test_paths_that_leave_the_scene_read_nothing(tmp_path):
    # camera rays that miss (and see the default sky) take the path loop's scattered branch from the first depth on
    from tests.frames.test_sky import _unlit_plane

    scene = read_scene(_unlit_plane(tmp_path / "plane.glb", half=1.0, camera=((0.0, 2.0, 2.0), (0.0, 0.0, 0.0), 0.9)))
    state, elements = scene.pose_frame(1), ElementMesh.build(scene)
    paths = CameraPaths(24, 18, 2, seed=4, frame=1)
    irradiance = np.random.default_rng(2).uniform(0.5, 1.0, (elements.n_vertices, 3))
    img = render_frame(state, elements, irradiance, paths, record_hits=True)
    assert 0 < len(img.map_hits.sample) < paths.width * paths.height * paths.spp  # some rays miss the plane
    assert np.array_equal(img.map_hits.indirect(elements, irradiance), img.indirect)
    with pytest.raises(ValueError):
        render_frame(state, elements, None, paths, record_hits=True)
