"""One OpenCL context, queue and built program per process, on a CPU device, cached on disk.

Platform choice is explicit (docs/15-opencl.md §1): ``PYOPENCL_CTX`` if set, else the
first platform whose name or version mentions PoCL, else any CPU device. PoCL caches compiled
kernels under ``POCL_CACHE_DIR`` (default ``~/.cache/pocl/kcache``); pyopencl's own invoker cache
lives under ``XDG_CACHE_HOME``, and so do the program binaries this module keeps
(:func:`binary_cache_dir`): a PoCL build from source costs 20-30 ms a program even when PoCL's cache
has it, a build from the binary 1-3 ms, and every worker process builds all seven programs (0.2 s
of each worker's first tasks, a serial cost of every extra worker, docs/13-cluster.md §4).
Programs are built once per process and source text, and kernels
are fetched once (``prg.name`` would build a new ``cl.Kernel`` on every access). Every program is
built with :data:`BUILD_OPTIONS`, the ``-D`` defines of the facts the Python side owns (the record
layout of kernels/record_layout.py, the luminance weights of kernels/colour.py), so the ``.cl``
files hold no copies. The buffer helpers at the end are shared by the kernels' wrappers.
"""
from __future__ import annotations

import hashlib
import os
import re
import warnings
from collections.abc import Sequence
from functools import lru_cache
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pyopencl as cl

from . import colour, record_layout

SOURCE_DIR = Path(__file__).resolve().parent
BUILD_OPTIONS = tuple(f"-D{name}={value}" for module in (record_layout, colour)
                      for name, value in module.BUILD_DEFINES.items())
WORK_GROUP = 64  # fixed local size of the lane kernels (PoCL compiles one kernel per local size)
LANES = 8  # rays or photons per work item of the lane kernels (lanes.cl)


class DeviceError(RuntimeError):
    """No OpenCL CPU device is available (an installation problem, not a bug of the caller)."""


@lru_cache(maxsize=1)
def device_context() -> tuple[cl.Context, cl.CommandQueue]:
    """The process's OpenCL context and in-order queue."""
    if os.environ.get("PYOPENCL_CTX"):
        ctx = cl.create_some_context(interactive=False)
        return ctx, cl.CommandQueue(ctx)
    try:
        platforms = cl.get_platforms()
    except cl.Error as err:
        raise DeviceError(f"no OpenCL platform ({err}); install Debian's pocl-opencl-icd (make setup)") from None
    ranked = sorted(platforms, key=lambda p: 0 if "pocl" in (p.name + p.version).lower() else 1)
    for platform in ranked:
        try:
            devices = platform.get_devices(device_type=cl.device_type.CPU)
        except cl.Error:
            continue
        if devices:
            ctx = cl.Context([devices[0]])
            return ctx, cl.CommandQueue(ctx)
    raise DeviceError("no OpenCL CPU device found; install Debian's pocl-opencl-icd (make setup)")


_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$', re.MULTILINE)


def expanded_source(name: str, seen: frozenset[str] = frozenset()) -> str:
    """``kernels/<name>.cl`` with its ``#include "x.cl"`` lines replaced by the files' text.

    PoCL's kernel cache is keyed by the program text, so inlining the includes makes a change to
    an included file rebuild every program that uses it (an include path would not)."""
    if name in seen:
        return ""
    text = (SOURCE_DIR / f"{name}.cl").read_text()
    return _INCLUDE.sub(lambda m: expanded_source(Path(m.group(1)).stem, seen | {name}), text)


@lru_cache(maxsize=None)
def program(name: str, options: tuple[str, ...] = ()) -> cl.Program:
    """Build ``kernels/<name>.cl`` (includes inlined) with :data:`BUILD_OPTIONS` and ``options``
    once per process, from the binary cache when it holds this build."""
    ctx, _ = device_context()
    return build_program(ctx, expanded_source(name), (*BUILD_OPTIONS, *options), binary_cache_dir(), name)[0]


def binary_cache_dir() -> Path:
    """Where built program binaries are kept: ``$XDG_CACHE_HOME/photonloom/opencl`` (default
    ``~/.cache``), beside pyopencl's cache and in the worker image's warmed cache (docker/Dockerfile)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "photonloom" / "opencl"


def build_program(ctx: cl.Context, source: str, options: Sequence[str], cache_dir: Path,
                  label: str = "program") -> tuple[cl.Program, bool]:
    """(program built for ``ctx``'s first device, whether it came from ``cache_dir``).

    The binary's file name hashes everything the build depends on (source, options, device,
    driver, pyopencl), so a changed kernel or an upgraded PoCL misses instead of loading stale
    code. A binary the driver refuses (truncated, foreign) is rebuilt from source and replaced; a
    cache that cannot be written only costs the next process the source build."""
    device = ctx.devices[0]
    ident = "\0".join([source, *options, device.name, device.version, device.driver_version,
                        device.platform.version, cl.VERSION_TEXT])
    path = cache_dir / f"{label}-{hashlib.sha256(ident.encode()).hexdigest()[:32]}.bin"
    with warnings.catch_warnings():
        # PoCL's build log carries ABI notes on some CPUs (double8 arguments without AVX-512);
        # pyopencl turns a non-empty log into a CompilerWarning although the build succeeded.
        warnings.simplefilter("ignore", cl.CompilerWarning)
        try:
            binary = path.read_bytes()
        except OSError:
            binary = None
        if binary:
            try:
                return cl.Program(ctx, [device], [binary]).build(options=list(options)), True
            except (cl.Error, RuntimeError):
                pass  # not a binary this driver takes: built from source below and replaced
        prg = cl.Program(ctx, source).build(options=list(options))
    tmp = path.with_name(f".{path.name}.{os.getpid()}.partial")
    try:
        cache_dir.mkdir(parents=True, exist_ok=True)
        tmp.write_bytes(prg.get_info(cl.program_info.BINARIES)[0])
        os.replace(tmp, path)  # whole or absent: processes building at once each rename a full file
    except OSError:
        try:
            tmp.unlink(missing_ok=True)  # a disk that filled mid-write leaves no partial file
        except OSError:
            pass
    return prg, False


@lru_cache(maxsize=None)
def kernel(program_name: str, kernel_name: str, options: tuple[str, ...] = ()) -> cl.Kernel:
    """A kernel object, fetched once (not thread-safe: workers run one thread each)."""
    return cl.Kernel(program(program_name, options), kernel_name)


_SCRATCH: dict[str, cl.Buffer] = {}


def scratch(name: str, nbytes: int) -> cl.Buffer:
    """A device buffer of at least ``nbytes`` kept per name for the process and reused by every
    call (allocating hundreds of MB per call costs page faults on a CPU device). Its contents are
    whatever the last user left; callers overwrite what they read."""
    buf = _SCRATCH.get(name)
    if buf is None or buf.size < nbytes:
        _SCRATCH.pop(name, None)
        ctx, _ = device_context()
        buf = _SCRATCH[name] = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, size=max(int(nbytes), 8))
    return buf


def device_table(ctx: cl.Context, a: np.ndarray, dtype: npt.DTypeLike) -> cl.Buffer:
    """A read-only device copy of a table (one element of zeros stands in for an empty one)."""
    a = np.ascontiguousarray(a, dtype=dtype)
    return cl.Buffer(ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                     hostbuf=a if a.size else np.zeros(1, dtype))


def device_input(ctx: cl.Context, a: np.ndarray) -> cl.Buffer:
    """A read-only device buffer over the host array (PoCL's CPU device uses host memory directly)."""
    return cl.Buffer(ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.USE_HOST_PTR, hostbuf=np.ascontiguousarray(a))


def device_output(ctx: cl.Context, a: np.ndarray) -> cl.Buffer:
    """A write-only device buffer over the host array ``a``; :func:`read_back` makes it current."""
    return cl.Buffer(ctx, cl.mem_flags.WRITE_ONLY | cl.mem_flags.USE_HOST_PTR, hostbuf=a)


def read_back(queue: cl.CommandQueue, arrays: Sequence[np.ndarray], buffers: Sequence[cl.Buffer]) -> None:
    """Wait for the kernel and make the host arrays behind ``buffers`` current (map, unmap)."""
    # Every map is enqueued without waiting and the queue is finished once: a blocking map per
    # array costs one round trip to PoCL's worker thread each (~25 us), which dominated the small
    # wavefronts at the end of a photon path.
    maps = [cl.enqueue_map_buffer(queue, b, cl.map_flags.READ, 0, a.shape, a.dtype, is_blocking=False)[0]
            for a, b in zip(arrays, buffers)]
    queue.finish()
    for a, mapped in zip(arrays, maps):
        if mapped.__array_interface__["data"][0] != a.__array_interface__["data"][0]:
            a[...] = mapped  # the runtime kept its own copy
        mapped.base.release(queue)  # the unmaps run before any later command of this in-order queue
