"""The embedded LocalCluster (pipeline/cluster.py): its workers get WORKER_ENV (one thread each,
PoCL's single-threaded device first) and the calling process keeps its own environment; Dask's
profiler, monitors and event-loop ticks are turned down there (LOCAL_DASK_CONFIG)."""
from __future__ import annotations

import os

from pipeline.cluster import LOCAL_DASK_CONFIG, WORKER_ENV, connect, group_size, grouped, run_tasks


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
            "from pipeline.images import LAYERS, write_exr\n"
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


def test_group_size_keeps_enough_tasks_for_every_worker():
    assert group_size(135, 2, 4) == 4  # ROOM's frames on two workers: 34 tasks
    assert group_size(135, 2, 2) == 2
    assert group_size(135, 8, 4) == 2  # 68 tasks, 8 a worker
    assert group_size(40, 2, 4) == 2
    assert group_size(10, 2, 4) == 1
    assert group_size(0, 0, 4) == 1


def test_groups_cover_the_calls_in_order_under_keys_their_members_decide():
    calls = [(f"job-{i}", {"i": i}) for i in range(7)]
    groups = grouped(calls, 3)
    assert [[k for k, _ in members] for _, members in groups] == [
        ["job-0", "job-1", "job-2"], ["job-3", "job-4", "job-5"], ["job-6"]]
    assert groups[-1][0] == "job-6"  # a group of one keeps its call's key
    assert len({key for key, _ in groups}) == 3
    other = grouped([calls[0], calls[2], calls[1]], 3)  # same first call, other members: another key
    assert other[0][0] != groups[0][0] and other[0][0].startswith("job-0-x3-")
    assert grouped(calls, 3) == groups  # stable


def _square(x: int) -> dict:
    return {"x": x, "square": x * x, "pid": os.getpid()}


def test_grouped_tasks_give_every_call_its_own_result_on_a_cluster():
    calls = [(f"square-{i}", {"x": i}) for i in range(11)]
    with connect("local", 2) as client:
        results = run_tasks(client, _square, calls, desc="square", progress=False, group=4)
    assert sorted(results) == sorted(k for k, _ in calls)
    assert all(results[f"square-{i}"]["square"] == i * i for i in range(11))
    assert run_tasks(None, _square, calls, desc="square", progress=False, group=4).keys() == results.keys()
