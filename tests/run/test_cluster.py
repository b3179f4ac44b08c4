"""The embedded LocalCluster (pipeline/run/cluster.py): its workers get WORKER_ENV (one thread each,
PoCL's single-threaded device first) and the calling process keeps its own environment; Dask's
profiler, monitors and event-loop ticks are turned down there (LOCAL_DASK_CONFIG)."""
from __future__ import annotations

import os

import pytest

from pipeline.run.cluster import LOCAL_DASK_CONFIG, TAIL_SHARE, WORKER_ENV, connect, group_sizes, grouped, run_tasks


def _worker_view() -> dict:
    from kernels.context import device_context

    device = device_context()[0].devices[0]
    return {"env": {k: os.environ.get(k) for k in WORKER_ENV}, "device": device.name,
            "units": device.max_compute_units}


def test_workers_get_the_worker_environment_and_the_caller_keeps_its_own(monkeypatch):
    for key in (*WORKER_ENV, "PYTHONHASHSEED"):  # (a variable the caller sets would win over WORKER_ENV)
        monkeypatch.delenv(key, raising=False)
    keys = (*WORKER_ENV, "PYTHONHASHSEED")
    before = {k: os.environ.get(k) for k in keys}
    with connect("local", 1) as client:
        assert {k: os.environ.get(k) for k in keys} == before  # restored as soon as the workers are up
        (view,) = client.run(_worker_view).values()
    assert {k: os.environ.get(k) for k in keys} == before
    assert view["env"] == WORKER_ENV
    assert view["device"].startswith("basic") and view["units"] == 1


def test_a_worker_writes_its_frames_in_its_own_thread(tmp_path):
    """WORKER_ENV's OpenImageIO options leave OpenEXR no compression pool: writing a frame's EXR
    starts no thread (with ``exr_threads=1`` it started one, which compressed beside the task)."""
    import subprocess
    import sys

    code = ("import os, numpy as np\n"
            "from pipeline.frames.images import LAYERS, write_exr\n"
            "a = np.ones((64, 64, 3), np.float32)\n"
            "before = len(os.listdir('/proc/self/task'))\n"
            f"write_exr({str(tmp_path / 'f.exr')!r}, a, a[..., 0], {{n: a for n in LAYERS}}, {{}})\n"
            "print(before, len(os.listdir('/proc/self/task')))\n")

    def threads_started(options: str) -> int:
        env = {**os.environ, **WORKER_ENV, "OPENIMAGEIO_OPTIONS": options}
        before, after = map(int, subprocess.run([sys.executable, "-c", code], env=env, check=True,
                                                capture_output=True, text=True).stdout.split())
        return after - before

    assert threads_started(WORKER_ENV["OPENIMAGEIO_OPTIONS"]) == 0
    assert threads_started("threads=1,exr_threads=1") == 1  # the check can fail: one pool thread more


def _profiler_and_monitors() -> dict:
    import dask

    return {k: dask.config.get(k) for k in LOCAL_DASK_CONFIG}


def _tick_seconds(dask_worker) -> float:
    return dask_worker._tick_interval


def _tick_seconds_of_scheduler(dask_scheduler) -> float:
    return dask_scheduler._tick_interval


def test_local_workers_run_without_the_profiler_unless_a_performance_report_is_asked_for(tmp_path):
    with connect("local", 1) as client:
        (quiet,) = client.run(_profiler_and_monitors).values()
        (tick,) = client.run(_tick_seconds).values()
        scheduler_tick = client.run_on_scheduler(_tick_seconds_of_scheduler)
    assert quiet == LOCAL_DASK_CONFIG
    assert tick == scheduler_tick == 1.0  # the servers took it: one event-loop health check a second, not 50
    with connect("local", 1, performance_report=str(tmp_path / "report.html")) as client:
        (reporting,) = client.run(_profiler_and_monitors).values()
    assert reporting["distributed.worker.profile.enabled"] is True  # the report shows the profile
    assert (tmp_path / "report.html").stat().st_size > 0


def test_groups_shrink_to_single_calls_as_the_work_runs_out():
    sizes = group_sizes(135, 2, 4)  # ROOM's composites on two workers
    assert sum(sizes) == 135 and max(sizes) == 4
    assert sizes == sorted(sizes, reverse=True)  # never growing towards the end
    assert sizes[-4:] == [1, 1, 1, 1]  # the last calls one a task: the workers finish together
    # each group at most 1/(TAIL_SHARE x workers) of the calls from it on (or one call)
    left = 135
    for size in sizes:
        assert size == 1 or size <= left // (TAIL_SHARE * 2)
        left -= size
    assert len(sizes) < 135 // 2  # fewer tasks than pairs of calls
    assert group_sizes(135, 1, 4) == [4] * 32 + [3, 2, 1, 1]  # one worker: the largest groups nearly to the end
    assert group_sizes(10, 8, 4) == [1] * 10
    assert group_sizes(0, 0, 4) == []


def test_a_chunks_groups_shrink_with_the_calls_after_it():
    # 16 calls heading 100: full groups; the same 16 as the last of a run: down to single calls
    assert group_sizes(16, 2, 4, left=100) == [4, 4, 4, 4]
    assert group_sizes(16, 2, 4) == [4, 3, 2] + [1] * 7
    assert group_sizes(5, 2, 4, left=3) == group_sizes(5, 2, 4)  # left counts at least these calls


def test_groups_cover_the_calls_in_order_under_keys_their_members_decide():
    calls = [(f"job-{i}", i) for i in range(7)]
    groups = grouped(calls, 3)
    assert [[k for k, _ in members] for _, members in groups] == [
        ["job-0", "job-1", "job-2"], ["job-3", "job-4", "job-5"], ["job-6"]]
    assert groups[-1][0] == "job-6"  # a group of one keeps its call's key
    assert len({key for key, _ in groups}) == 3
    other = grouped([calls[0], calls[2], calls[1]], 3)  # same first call, other members: another key
    assert other[0][0] != groups[0][0] and other[0][0].startswith("job-0-x3-")
    assert grouped(calls, 3) == groups  # stable
    assert grouped(calls, [3, 3, 1]) == groups  # sizes one by one
    assert [len(m) for _, m in grouped(calls, [4, 2, 1])] == [4, 2, 1]
    with pytest.raises(ValueError):
        grouped(calls, [3, 3])  # sizes that leave calls out are a bug


def _square(x: int) -> dict:
    return {"x": x, "square": x * x, "pid": os.getpid()}


def test_grouped_tasks_give_every_call_its_own_result_on_a_cluster():
    calls = [(f"square-{i}", i) for i in range(11)]
    with connect("local", 2) as client:
        results = run_tasks(client, _square, calls, desc="square", progress=False, group=4)
    assert sorted(results) == sorted(k for k, _ in calls)
    assert all(results[f"square-{i}"]["square"] == i * i for i in range(11))
    assert run_tasks(None, _square, calls, desc="square", progress=False, group=4).keys() == results.keys()
