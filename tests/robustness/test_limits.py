"""Limits that keep memory and time bounded by what the input holds (docs/14-robustness.md §1):
frame ranges and timelines (pipeline/scene/timeline.py), worker counts and waits for a cluster
(pipeline/run/cluster.py)."""
from __future__ import annotations

import tracemalloc

import pytest

from pipeline.errors import LoomError
from pipeline.run.cluster import check_workers, completed, connect
from pipeline.scene import Timeline, parse_frame_range, read_scene
from pipeline.scene.timeline import MAX_FRAMES


@pytest.mark.parametrize("spec, says", [
    ("1-1000000000", "outside the timeline"),
    ("1-100,200-1000000000x7", "outside the timeline"),
    ("0", "outside the timeline"),
])
def test_huge_frame_ranges_are_refused_before_a_frame_is_listed(spec, says):
    tracemalloc.start()
    try:
        with pytest.raises(LoomError, match=says):
            Timeline(fps=30, frames=135).select(spec)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 1 << 20  # no list of a billion frames was ever made


def test_a_range_naming_more_than_the_limit_is_refused_without_a_timeline():
    tracemalloc.start()
    try:
        with pytest.raises(LoomError, match="more than 100,000 frames"):
            parse_frame_range("1-1000000000")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 1 << 20
    assert parse_frame_range(f"1-{MAX_FRAMES}")[-1] == MAX_FRAMES  # the limit itself is allowed


def test_a_timeline_beyond_the_limit_cannot_exist():
    with pytest.raises(LoomError, match="1 to 100,000"):
        Timeline(fps=30, frames=MAX_FRAMES + 1)
    assert Timeline(fps=30, frames=MAX_FRAMES).last == MAX_FRAMES


@pytest.mark.parametrize("workers", [0, -1, 10_000, 2.5, True])
def test_bad_worker_counts_are_refused(workers):
    with pytest.raises(LoomError, match="--workers"):
        check_workers(workers)


def test_connect_refuses_bad_workers_before_starting_a_cluster():
    with pytest.raises(LoomError, match="--workers"):
        with connect("local", -1):
            pass
    assert check_workers(None) is None and check_workers(2) == 2


def _double(x):
    return 2 * x


def test_waiting_on_a_cluster_without_workers_ends_with_an_error():
    """A real scheduler with no worker: the tasks can never run; the wait is bounded."""
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=0, processes=False, dashboard_address=":0") as cluster, Client(cluster) as client:
        futures = [client.submit(_double, i, pure=False) for i in range(3)]
        with pytest.raises(LoomError, match="cluster has none"):
            list(completed(client, futures, workerless_timeout=3.0))


def test_waiting_on_a_cluster_with_a_worker_returns_every_result():
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0") as cluster, \
            Client(cluster) as client:
        futures = [client.submit(_double, i, pure=False) for i in range(5)]
        assert sorted(r for _, r in completed(client, futures, workerless_timeout=3.0)) == [0, 2, 4, 6, 8]


def test_files_outside_the_scene_folder_need_the_explicit_opt_in(tmp_path, monkeypatch):
    """Item 6: a buffer beside the scene's folder is refused, and read once PHOTONLOOM_ALLOW_OUTSIDE_FILES=1."""
    import json

    from pipeline.scene.gltf import ALLOW_OUTSIDE_ENV
    from tests.robustness.cases import base_builder, split_glb

    doc, binary = split_glb(base_builder().to_glb_bytes())
    (tmp_path / "shared.bin").write_bytes(binary)
    (tmp_path / "scenes").mkdir()
    doc["buffers"][0]["uri"] = "../shared.bin"
    path = tmp_path / "scenes" / "scene.gltf"
    path.write_text(json.dumps(doc))
    monkeypatch.delenv(ALLOW_OUTSIDE_ENV, raising=False)
    with pytest.raises(LoomError, match="outside the scene's folder"):
        read_scene(path)
    monkeypatch.setenv(ALLOW_OUTSIDE_ENV, "1")
    assert read_scene(path).n_triangles == 14
