"""The embedded LocalCluster (pipeline/cluster.py): its workers get WORKER_ENV (one thread each,
PoCL's single-threaded device first) and the calling process keeps its own environment; Dask's
profiler and monitors are turned down there (LOCAL_DASK_CONFIG)."""
from __future__ import annotations

import os

from pipeline.cluster import LOCAL_DASK_CONFIG, WORKER_ENV, connect


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


def _profiler_and_monitors() -> dict:
    import dask

    return {k: dask.config.get(k) for k in LOCAL_DASK_CONFIG}


def test_local_workers_run_without_the_profiler_unless_a_performance_report_is_asked_for(tmp_path):
    with connect("local", 1) as client:
        (quiet,) = client.run(_profiler_and_monitors).values()
    assert quiet == LOCAL_DASK_CONFIG
    with connect("local", 1, performance_report=str(tmp_path / "report.html")) as client:
        (reporting,) = client.run(_profiler_and_monitors).values()
    assert reporting["distributed.worker.profile.enabled"] is True  # the report shows the profile
    assert (tmp_path / "report.html").stat().st_size > 0
