"""One OpenCL context, queue and built program per process, on a CPU device, cached on disk.

Platform choice is explicit (shared/notes/ecosystem.md §3): ``PYOPENCL_CTX`` if set, else the
first platform whose name or version mentions PoCL, else any CPU device. PoCL caches compiled
kernels under ``POCL_CACHE_DIR`` (default ``~/.cache/pocl/kcache``); pyopencl's own invoker cache
lives under ``XDG_CACHE_HOME``. Programs are built once per process and source text, and kernels
are fetched once (``prg.name`` would build a new ``cl.Kernel`` on every access).
"""
from __future__ import annotations

import os
import re
import warnings
from functools import lru_cache
from pathlib import Path

import pyopencl as cl

from pipeline.errors import LoomError

SOURCE_DIR = Path(__file__).resolve().parent


@lru_cache(maxsize=1)
def device_context() -> tuple[cl.Context, cl.CommandQueue]:
    """The process's OpenCL context and in-order queue."""
    if os.environ.get("PYOPENCL_CTX"):
        ctx = cl.create_some_context(interactive=False)
        return ctx, cl.CommandQueue(ctx)
    try:
        platforms = cl.get_platforms()
    except cl.Error as err:
        raise LoomError(f"no OpenCL platform ({err}); install Debian's pocl-opencl-icd (make setup)",
                        field="opencl") from None
    ranked = sorted(platforms, key=lambda p: 0 if "pocl" in (p.name + p.version).lower() else 1)
    for platform in ranked:
        try:
            devices = platform.get_devices(device_type=cl.device_type.CPU)
        except cl.Error:
            continue
        if devices:
            ctx = cl.Context([devices[0]])
            return ctx, cl.CommandQueue(ctx)
    raise LoomError("no OpenCL CPU device found; install Debian's pocl-opencl-icd (make setup)",
                    field="opencl")


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
    """Build ``kernels/<name>.cl`` (includes inlined) once per process."""
    ctx, _ = device_context()
    with warnings.catch_warnings():
        # PoCL's build log carries ABI notes on some CPUs (double8 arguments without AVX-512);
        # pyopencl turns a non-empty log into a CompilerWarning although the build succeeded.
        warnings.simplefilter("ignore", cl.CompilerWarning)
        return cl.Program(ctx, expanded_source(name)).build(options=list(options))


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
