"""Where tasks run: an embedded LocalCluster (default), the synchronous scheduler, or a farm.

Workers run one thread each: Embree and PoCL start their own all-core thread pools, and
``cl.Kernel`` is not safe for concurrent use (docs/15-opencl.md §3). ``run_tasks`` submits
plain functions with readable keys, retries failed tasks, and shows a progress bar on stderr.
"""
from __future__ import annotations

import logging
import multiprocessing
import os
import queue
import time
from contextlib import contextmanager
from multiprocessing import forkserver
from typing import TYPE_CHECKING, Any, Callable, Iterable, Iterator

from tqdm import tqdm

from pipeline.config import stable_digest
from pipeline.errors import LoomError

if TYPE_CHECKING:
    from distributed import Client, Future  # imported once a cluster starts

# Environment for worker processes: one thread per library, so processes x 1 thread fill the machine.
WORKER_ENV = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "POCL_MAX_PTHREAD_COUNT": "1",
    "POCL_CPU_MAX_CU_COUNT": "1",
    # PoCL's single-threaded "basic" device first (kernels/context.py takes the first CPU device),
    # its threaded one as the fallback where a PoCL build lacks it: a one-thread worker gains
    # nothing from a thread pool, and handing every command to a pool thread and waiting for it
    # made photon tracing ~20 % slower (ROOM, 30 frames of 40,000 photons, best of 3, alternated:
    # 79.4 / 72.9 ms a frame threaded against 62.3 / 57.8 basic). Same compiler, same bits.
    "POCL_DEVICES": "basic pthread",
    # OpenImageIO's own pool (default: one thread per core) compresses EXR scanlines in parallel:
    # a lone worker then borrowed the idle core (1.6 cores for an EXR write), and two workers
    # oversubscribed the machine (frame writes 54 -> 86 ms each). exr_threads=1 is not one thread
    # but OpenEXR's pool of one *more*, which compresses while the caller writes (a ROOM render of
    # 40 frames: 1.03 s in that thread beside the task's 6.36 s). -1 is no pool: all in the task's
    # own thread
    "OPENIMAGEIO_OPTIONS": "threads=1,exr_threads=-1",
    # glibc hands freed memory back after every photon batch, so the next batch page-faults ~7 MB
    # of fresh memory (1,860 faults a write); keeping up to 128 MiB cuts a store write from 14 to
    # 10 ms (measured with `loom bench render`)
    "MALLOC_MMAP_THRESHOLD_": "33554432",
    "MALLOC_TRIM_THRESHOLD_": "134217728",
}
# What a worker process imports before its first task: imported once in the fork server that
# forks the local workers (see :func:`start_worker_server`), not once per worker and run
WORKER_PRELOAD = ("distributed", "numpy", "pyopencl", "embreex", "zarr", "OpenImageIO",
                  "workers.shoot", "workers.reconstruct", "workers.composite")
TASK_RETRIES = 3
# Bounds on waiting for a cluster: worker processes of --scheduler local (more than 4 per core
# only thrash), and how long tasks may wait while the cluster has no worker at all (a cluster
# that lost or never got its workers) before the run stops with an error instead of hanging.
MAX_WORKERS_PER_CORE = 4
WORKERLESS_TIMEOUT_S = 60.0
_POLL_S = 2.0
# Dask's bookkeeping on a local cluster, where it shares the cores with the tasks. Each worker's
# event loop sampled its task thread's stack 100 times a second for the dashboard's profile (2 of
# its 5 s of CPU in a 1-worker ROOM render of 48 s, holding the GIL while it walks the stack), and
# read /proc for memory 10 (the worker's and its nanny's monitors) and 2 times a second (the system
# monitor). On two cores that CPU comes out of the tasks' share. Off and slower here: a
# --performance-report run keeps the profiler on, as its report shows the profile. Memory limits
# still hold, checked every second instead of every 0.1 s. And every Dask server (the scheduler,
# the nannies, each worker) woke its event loop 50 times a second only to measure how late the
# wake-up was (``distributed.admin.tick``, a diagnostic: the "event loop was unresponsive" warning
# after 3 s, a dashboard gauge): an idle 2-worker cluster spent 0.73 s of CPU in the client process
# and 0.67 s in the workers every 15 s that way, 0.21 and 0.14 s with one tick a second.
LOCAL_DASK_CONFIG = {
    "distributed.admin.tick.interval": "1s",
    "distributed.worker.profile.enabled": False,
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.worker.memory.monitor-interval": "1s",
}


_DASK_LOGGERS = ("distributed", "tornado", "asyncio")


def silence_dask_logs() -> None:
    """Run on each worker as the run ends: its Dask loggers say nothing more (close_local)."""
    for name in _DASK_LOGGERS:
        logging.getLogger(name).setLevel(logging.CRITICAL)


def close_local(client: Any, cluster: Any, timeout: float = 10.0) -> None:
    """Close a LocalCluster so nothing of it outlives the run: with Dask's loggers in this process
    (the nannies') silenced, the nannies stop their workers first and this waits until the
    scheduler has none (a worker's heartbeat to a closed scheduler is what printed a
    CommClosedError traceback after a successful render), then the client closes before the cluster.
    The workers' own loggers are silenced first too: on a busy machine a worker whose heartbeat the
    closing cut short logged "Failed to communicate with scheduler" with its traceback."""
    loggers = [logging.getLogger(name) for name in _DASK_LOGGERS]
    levels = [logger.level for logger in loggers]
    for logger in loggers:
        logger.setLevel(logging.CRITICAL)
    try:
        try:
            client.run(silence_dask_logs)
            cluster.scale(0)
            deadline = time.monotonic() + timeout
            while client.scheduler_info().get("workers") and time.monotonic() < deadline:
                time.sleep(0.05)
        except (OSError, TimeoutError, RuntimeError):  # a scheduler already gone has no workers left
            pass
        client.close()
        cluster.close()
    finally:
        for logger, level in zip(loggers, levels):
            logger.setLevel(level)


def _restore_environ(saved: dict[str, str | None]) -> None:
    """Put the variables of ``saved`` back as they were (removing those that were unset)."""
    for key, value in saved.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value


def check_workers(workers: int | None) -> int | None:
    """``--workers``: None (one per core) or an integer in [1, 4 x cores]; 0 and negatives are errors."""
    if workers is None:
        return None
    limit = MAX_WORKERS_PER_CORE * (os.cpu_count() or 1)
    if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= limit:
        raise LoomError(f"must be a number of worker processes in [1, {limit}] ({MAX_WORKERS_PER_CORE} per core), "
                        f"got {workers!r}", field="--workers")
    return workers


def start_worker_server() -> None:
    """Start, if not running, the fork server that the local cluster's worker processes are forked
    from (multiprocessing's ``forkserver``, which Dask's nannies use with
    ``distributed.worker.multiprocessing-method``), with the worker environment and
    :data:`WORKER_PRELOAD` imported.

    Why: spawned workers each started a new interpreter and imported distributed, NumPy, PyOpenCL,
    Embree and our tasks' modules (about 0.8 s for the cluster and 0.4 s more before a worker's
    first task, both serial in every render); forked from a server that did this once, a cluster
    starts in about 0.1 s, and the server starts while the client is still importing and loading
    the scene (pipeline/cli/render.py). The server is a fresh single-threaded interpreter (not the
    client, whose threads a fork would copy badly) and holds no device: each worker still makes its
    own OpenCL context and Embree scenes. The environment must be the server's from its start
    (a forked child keeps it), hence :data:`WORKER_ENV` here and not only in the nannies'."""
    saved = {k: os.environ.get(k) for k in (*WORKER_ENV, "PYTHONHASHSEED")}
    try:
        os.environ.update(WORKER_ENV)
        os.environ["PYTHONHASHSEED"] = "6640"  # Dask's nannies' value: every worker hashes alike
        multiprocessing.get_context("forkserver").set_forkserver_preload(list(WORKER_PRELOAD))
        forkserver.ensure_running()
    finally:
        _restore_environ(saved)


@contextmanager
def connect(scheduler: str = "local", workers: int | None = None, *, performance_report: str | None = None,
            echo: Callable[[str], None] | None = None) -> Iterator[object | None]:
    """Yield a ``distributed.Client`` (or None for ``synchronous``) for the duration of a run.

    ``local`` starts a LocalCluster of worker processes sized to the machine (``workers`` or one
    per core); ``synchronous`` runs tasks in this process; anything else is a scheduler address.
    ``echo`` gets the dashboard link; ``performance_report`` is an HTML file for Dask's own report
    of the run (distributed.performance_report).
    """
    workers = check_workers(workers)
    if scheduler == "synchronous":
        if performance_report:
            raise LoomError("needs a Dask cluster (--scheduler local or an address)", field="--performance-report")
        yield None
        return
    import dask  # imported once a cluster starts (the fork server starts first)
    from distributed import Client, LocalCluster

    logging.getLogger("distributed").setLevel(logging.WARNING)

    if scheduler == "local":
        n = workers if workers is not None else os.cpu_count() or 1
        # A nanny sets its pre-spawn variables in its own process's environment and leaves them
        # there; a LocalCluster's nannies live in this process, so without the restore the caller's
        # own OpenCL would find one thread and the basic device after the run.
        saved = {k: os.environ.get(k) for k in (*WORKER_ENV, "PYTHONHASHSEED")}
        start_worker_server()
        try:
            quiet = {k: v for k, v in LOCAL_DASK_CONFIG.items()
                     if not (performance_report and k == "distributed.worker.profile.enabled")}
            with dask.config.set({"distributed.nanny.pre-spawn-environ": WORKER_ENV,
                                  "distributed.worker.multiprocessing-method": "forkserver",
                                  "distributed.worker.daemon": False, **quiet}):
                # The scheduler serves HTTP (metrics) even without a dashboard, on 8787 unless told
                # otherwise, and warns when another cluster holds it: any free port instead.
                cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                                       dashboard_address=":0", silence_logs=logging.WARNING)
                client = Client(cluster)
            _restore_environ(saved)
            try:
                with _reporting(client, performance_report, echo):
                    yield client
            finally:
                close_local(client, cluster)
        finally:
            _restore_environ(saved)
        return
    if "://" not in scheduler:
        raise LoomError(f"{scheduler!r} is not local, synchronous or a scheduler address like "
                        "tcp://127.0.0.1:8786", field="--scheduler")
    try:
        client = Client(scheduler, timeout="20s")
    except OSError as err:
        reason = " ".join(str(err).split())
        raise LoomError(f"cannot reach the scheduler {scheduler} within 20 s ({reason})", field="--scheduler") from None
    try:
        with _reporting(client, performance_report, echo):
            yield client
    finally:
        client.close()


@contextmanager
def _reporting(client, performance_report: str | None, echo):
    if echo is not None and getattr(client, "dashboard_link", None):
        echo(f"dask dashboard: {client.dashboard_link}")
    if not performance_report:
        yield
        return
    from distributed import performance_report as report  # imported once a cluster starts

    with report(filename=performance_report):
        yield


def task_key(name: str, *where: str) -> str:
    """``name`` tagged with a digest of where the task writes (store, output folder).

    A submission whose key the cluster still holds gets the earlier task's result without running
    (distributed reuses keys), so two runs of the same work into different stores (the error
    benchmark's warm-up and first run, two renders on one long-lived scheduler) must never share a
    key: the second run's files were silently not written."""
    return f"{name}-{stable_digest(list(where))[:8]}"


# Every Dask task costs the cluster about 8 ms of CPU besides its own work (5 ms in the scheduler
# and client, 3 ms in the worker's event loop: 300 empty tasks on 2 local workers, this machine),
# CPU that on a small machine comes out of the other tasks' share. Short tasks of the same kind
# (a frame's photon batch, about 0.06 s; a frame's composite, about 0.17 s) therefore go in groups.
# The groups shrink towards the end of a run of calls, as in guided self-scheduling (Polychronopoulos
# and Kuck, IEEE Trans. Computers 36(12), 1987), where each task takes a share of the work left: a
# group holds at most 1/(TAIL_SHARE x workers) of the calls from it on, so the last ones are single
# calls and the workers run out of work together (a last group of 4 composites would leave the other
# worker idle 0.5 s).
TAIL_SHARE = 2


def group_sizes(n_calls: int, n_workers: int, largest: int, left: int | None = None) -> list[int]:
    """Sizes of the consecutive groups of ``n_calls`` calls: each ``left_here // (TAIL_SHARE x
    n_workers)`` capped to [1, ``largest``], ``left_here`` the calls from the group's first on.
    ``left``: calls left from the first of these on when they head a longer run (default
    ``n_calls``), as a chunk's composites head those of the chunks after it."""
    left = n_calls if left is None else max(left, n_calls)
    sizes, done = [], 0
    while done < n_calls:
        size = max(1, min(largest, n_calls - done, (left - done) // (TAIL_SHARE * max(n_workers, 1))))
        sizes.append(size)
        done += size
    return sizes


def run_group(func: Callable, requests: list) -> list:
    """Dask task: ``func(request)`` for each request in order (see :func:`grouped`)."""
    return [func(request) for request in requests]


def grouped(calls: list[tuple[str, Any]], sizes: int | list[int]) -> list[tuple[str, list[tuple[str, Any]]]]:
    """Consecutive runs of ``sizes`` calls (one size for all, or :func:`group_sizes`), each under a
    key naming its first call, its size and a digest of all its keys (a group with other members
    never reuses another's result)."""
    if isinstance(sizes, int):
        sizes = [sizes] * -(-len(calls) // max(sizes, 1))
    out, start = [], 0
    for size in sizes:
        members = calls[start:start + size]
        start += size
        if not members:
            break
        key = members[0][0] if len(members) == 1 else \
            f"{members[0][0]}-x{len(members)}-{stable_digest([k for k, _ in members])[:6]}"
        out.append((key, members))
    if start < len(calls):
        raise ValueError(f"group sizes {sizes} cover {start} of {len(calls)} calls")
    return out


def submit_grouped(client: Client, func: Callable, calls: list[tuple[str, Any]], sizes: int | list[int], *,
                   priority: int = 0) -> dict[Future, list[str]]:
    """Submit ``calls`` in groups of ``sizes`` (:func:`grouped`, :func:`run_group`) at Dask's ``priority``;
    {future: its calls' keys}."""
    return {client.submit(run_group, func, [request for _, request in members], key=key, retries=TASK_RETRIES,
                          pure=False, priority=priority): [k for k, _ in members]
            for key, members in grouped(calls, sizes)}


def run_tasks(client: Client | None, func: Callable, calls: Iterable[tuple[str, Any]], *, desc: str,
              progress: bool = True, group: int | list[int] = 1) -> dict[str, object]:
    """Run ``func(request)`` for every ``(key, request)`` and return ``{key: result}``.

    On a cluster, tasks are submitted with their key (a readable label that also makes a
    resubmission of the same work reuse it) and ``TASK_RETRIES`` retries, ``group`` calls to a task
    (or the sizes of :func:`group_sizes`; :func:`grouped`); results are collected as they complete,
    with a tqdm bar on stderr.
    """
    calls = list(calls)
    results: dict[str, object] = {}
    bar = tqdm(total=len(calls), desc=desc, unit="task", disable=not progress or not calls,
               dynamic_ncols=True, leave=False)
    try:
        if client is None:
            for key, request in calls:
                results[key] = func(request)
                bar.update()
            return results
        members = submit_grouped(client, func, calls, group)
        for future, group_results in completed(client, members):
            results.update(zip(members[future], group_results))
            bar.update(len(group_results))
        return results
    finally:
        bar.close()


def completed(client: Client, futures: Iterable[Future],
              workerless_timeout: float = WORKERLESS_TIMEOUT_S) -> Iterator[tuple[object, object]]:
    """``(future, result)`` as futures finish, like ``distributed.as_completed(with_results=True)``,
    but bounded: a LoomError once tasks have waited ``workerless_timeout`` seconds with no worker in
    the cluster (all died, or none ever started), instead of waiting forever.

    Each future reports itself on a queue when done (``add_done_callback``): O(n) for n futures,
    where calling ``distributed.wait(pending, return_when=FIRST_COMPLETED)`` once a completion
    made a waiter for every pending future each time, O(n^2): 300 short tasks cost the client
    process 1.2-1.3 CPU seconds that way against 0.8 (docs/13-cluster.md §3)."""
    pending = list(futures)
    finished: queue.SimpleQueue = queue.SimpleQueue()
    for future in pending:
        future.add_done_callback(finished.put)
    since = None
    for done in range(len(pending)):
        while True:
            try:
                future = finished.get(timeout=min(_POLL_S, workerless_timeout))
                break
            except queue.Empty:
                pass
            if client.nthreads():
                since = None
            elif since is None:
                since = time.monotonic()
            elif time.monotonic() - since > workerless_timeout:
                raise LoomError(f"{len(pending) - done} task(s) waited {workerless_timeout:.0f} s for a Dask worker "
                                "and the cluster has none (its workers died or never started)",
                                field="--scheduler")
        since = None
        yield future, future.result()


def result(client: Client, future: Future) -> Any:
    """The result of one future, waited for as :func:`completed` waits."""
    return next(completed(client, [future]))[1]
