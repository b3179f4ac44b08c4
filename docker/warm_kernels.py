"""Warm PoCL's kernel cache (POCL_CACHE_DIR), pyopencl's and the program binaries
(XDG_CACHE_HOME, kernels/context.py) for the worker tasks.

Run at image build time (docker/Dockerfile) with the installed package, not the checkout:

    python /usr/local/share/photonloom/warm_kernels.py

1. Builds every OpenCL program the tasks build, through ``kernels.context.program`` with the
   options the tasks pass (none): photons (pipeline/photons/tracing.py: emit, scatter), reconstruction
   (pipeline/collection/maps.py: temporal, gather, filter) and composite (workers/composite.py: camera,
   surface). PoCL keys its cache by program text, build options and device, so these are the
   entries a worker looks up; kernels.context keeps each program's binary under
   ``$XDG_CACHE_HOME/photonloom/opencl`` keyed the same way (a worker loads it in 1-3 ms instead of
   building from source in 20-30 ms).
2. Renders two 32x24 frames of the built-in cornell scene in this process (``--scheduler
   synchronous``, a temporary directory): PoCL compiles each kernel's work-group function at its
   first launch, so running the tasks once caches those too (kernels with a fixed work-group size
   exactly; those whose local size PoCL chooses from the launch size, for the sizes seen here).

The cache is only reused on a CPU like the build machine's (PoCL compiles for the host CPU and keys
the cache by device); elsewhere the workers rebuild it on first use, which is slower, not wrong.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

# Program name -> the task that builds it. tests/farm/test_container.py checks this against every
# kernel("name", ...) call in kernels/, workers/ and pipeline/.
WORKER_PROGRAMS = {
    "emit": "photons", "scatter": "photons",
    "temporal": "reconstruction", "gather": "reconstruction", "filter": "reconstruction",
    "camera": "composite", "surface": "composite",
}
BUILD_OPTIONS: tuple[str, ...] = ()  # kernels.context.kernel's default; no task passes others


def cache_files(path: str | None) -> int:
    return sum(1 for p in Path(path).rglob("*") if p.is_file()) if path and Path(path).is_dir() else 0


def main() -> int:
    from kernels.context import device_context, program

    ctx, _ = device_context()
    print(f"warming OpenCL programs on {ctx.devices[0].name} ({ctx.devices[0].platform.name})", flush=True)
    for name, task in WORKER_PROGRAMS.items():
        program(name, BUILD_OPTIONS)
        print(f"  built {name}.cl ({task})", flush=True)
    with tempfile.TemporaryDirectory(prefix="loom-warm-") as tmp:
        loom = [sys.executable, "-m", "pipeline"]
        scene = os.path.join(tmp, "cornell.glb")
        subprocess.run(loom + ["scene", "cornell", "-o", scene], check=True, cwd=tmp)
        subprocess.run(loom + ["render", scene, "--out", os.path.join(tmp, "out"), "--scheduler", "synchronous",
                               "--frames", "1-2", "--resolution", "32x24", "--spp", "1", "--photons", "2000"],
                       check=True, cwd=tmp, stdout=subprocess.DEVNULL)
    cache = os.environ.get("POCL_CACHE_DIR")
    n = cache_files(cache)
    print(f"PoCL kernel cache {cache or '(default)'}: {n} files", flush=True)
    if cache and n == 0:
        print("warm_kernels: PoCL wrote nothing to POCL_CACHE_DIR", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
