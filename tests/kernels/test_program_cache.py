"""The program binary cache of kernels/context.py: a build is stored, loaded back, gives the same
results as the source build, and a broken or foreign entry is rebuilt, never trusted."""
from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest

from kernels.context import BUILD_OPTIONS, build_program, device_context, expanded_source

SOURCE = """
__kernel void scale(__global const float *a, __global float *b, const float s) {
    size_t i = get_global_id(0);
    b[i] = sqrt(a[i]) * s + a[i] / (s + 1.0f);
}
"""


def _run(prg: cl.Program) -> np.ndarray:
    ctx, queue = device_context()
    a = np.linspace(0.0, 7.0, 1000, dtype=np.float32)
    b = np.empty_like(a)
    mf = cl.mem_flags
    da = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a)
    db = cl.Buffer(ctx, mf.WRITE_ONLY, b.nbytes)
    cl.Kernel(prg, "scale")(queue, a.shape, None, da, db, np.float32(3.1))
    cl.enqueue_copy(queue, b, db)
    return b


def test_stored_then_loaded_with_the_same_results(tmp_path):
    ctx, _ = device_context()
    built, cached = build_program(ctx, SOURCE, BUILD_OPTIONS, tmp_path, "scale")
    assert not cached
    files = list(tmp_path.glob("scale-*.bin"))
    assert len(files) == 1 and files[0].stat().st_size > 0
    assert not list(tmp_path.glob(".*partial"))
    loaded, cached = build_program(ctx, SOURCE, BUILD_OPTIONS, tmp_path, "scale")
    assert cached
    assert _run(loaded).tobytes() == _run(built).tobytes()


def test_a_real_program_round_trips(tmp_path):
    """One of the renderer's own programs (includes inlined, the -D options) loads from its binary."""
    ctx, _ = device_context()
    source = expanded_source("temporal")
    first, cached_first = build_program(ctx, source, BUILD_OPTIONS, tmp_path, "temporal")
    second, cached_second = build_program(ctx, source, BUILD_OPTIONS, tmp_path, "temporal")
    assert (cached_first, cached_second) == (False, True)
    names = lambda p: sorted(k.function_name for k in p.all_kernels())  # noqa: E731
    assert names(first) == names(second) and "windows" in names(second)


@pytest.mark.parametrize("junk", [b"", b"not a binary", bytes(range(256)) * 64])
def test_a_broken_entry_is_rebuilt_and_replaced(tmp_path, junk):
    ctx, _ = device_context()
    build_program(ctx, SOURCE, BUILD_OPTIONS, tmp_path, "scale")
    (entry,) = tmp_path.glob("scale-*.bin")
    good = _run(build_program(ctx, SOURCE, BUILD_OPTIONS, tmp_path, "scale")[0])
    entry.write_bytes(junk)
    prg, cached = build_program(ctx, SOURCE, BUILD_OPTIONS, tmp_path, "scale")
    assert not cached and _run(prg).tobytes() == good.tobytes()
    assert build_program(ctx, SOURCE, BUILD_OPTIONS, tmp_path, "scale")[1]  # the entry was replaced


def test_other_source_or_options_miss(tmp_path):
    ctx, _ = device_context()
    build_program(ctx, SOURCE, BUILD_OPTIONS, tmp_path, "scale")
    assert not build_program(ctx, SOURCE, (*BUILD_OPTIONS, "-DUNUSED=1"), tmp_path, "scale")[1]
    assert not build_program(ctx, SOURCE.replace("3.1", "3.2") + "\n", BUILD_OPTIONS, tmp_path, "scale")[1]
    assert len(list(tmp_path.glob("scale-*.bin"))) == 3


def test_an_unwritable_cache_still_builds(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("a file where the cache directory would be")
    ctx, _ = device_context()
    prg, cached = build_program(ctx, SOURCE, BUILD_OPTIONS, blocker / "opencl", "scale")
    assert not cached and _run(prg).shape == (1000,)
