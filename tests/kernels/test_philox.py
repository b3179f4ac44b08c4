"""Philox4x32-10: Random123's known answers, and the OpenCL version equals the NumPy one."""
from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest

from kernels.context import device_context
from kernels.philox import philox4x32_10, uniforms

# Known-answer vectors of Random123 (kat_vectors, philox4x32_10)
KAT = [
    ((0, 0, 0, 0), (0, 0), (0x6627E8D5, 0xE169C58D, 0xBC57AC4C, 0x9B00DBD8)),
    ((0xFFFFFFFF,) * 4, (0xFFFFFFFF, 0xFFFFFFFF), (0x408F276D, 0x41C83B0E, 0xA20BC7C6, 0x6D5451FD)),
    ((0x243F6A88, 0x85A308D3, 0x13198A2E, 0x03707344), (0xA4093822, 0x299F31D0),
     (0xD16CFE09, 0x94FDCCEB, 0x5001E420, 0x24126EA1)),
]


@pytest.mark.parametrize("counter, key, expected", KAT)
def test_known_answers(counter, key, expected):
    out = philox4x32_10(np.array([counter], np.uint32), key)[0]
    assert tuple(int(x) for x in out) == expected


def test_opencl_equals_numpy(rng):
    ctx, queue = device_context()
    src = """
    #include "philox.cl"
    __kernel void draw(__global const uint4 *c, const uint k0, const uint k1, __global uint4 *out) {
        size_t i = get_global_id(0);
        out[i] = philox4x32_10(c[i], (uint2)(k0, k1));
    }"""
    from kernels.context import SOURCE_DIR

    prg = cl.Program(ctx, src).build(options=["-I", str(SOURCE_DIR)])
    counters = rng.integers(0, 2**32, size=(4096, 4), dtype=np.uint64).astype(np.uint32)
    counters[:3] = [c for c, _, _ in KAT]
    buf = cl.Buffer(ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=counters)
    out = np.empty_like(counters)
    out_buf = cl.Buffer(ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    cl.Kernel(prg, "draw")(queue, (len(counters),), None, buf, np.uint32(0xDEADBEEF), np.uint32(7), out_buf)
    cl.enqueue_copy(queue, out, out_buf)
    np.testing.assert_array_equal(out, philox4x32_10(counters, (0xDEADBEEF, 7)))


def test_uniforms_are_uniform_and_in_range():
    u = uniforms(np.arange(200_000), 3, (1, 2))
    assert u.min() >= 0.0 and u.max() < 1.0
    hist, _ = np.histogram(u.ravel(), bins=20, range=(0, 1))
    expected = u.size / 20
    chi2 = ((hist - expected) ** 2 / expected).sum()
    assert chi2 < 45.3  # 99.9th percentile of chi-squared with 19 degrees of freedom
    assert not np.array_equal(uniforms(np.arange(10), 3, (1, 2)), uniforms(np.arange(10), 4, (1, 2)))


def test_eight_lane_philox_equals_numpy(rng):
    """PHILOX8_10 (lanes.cl), what the emission and bounce kernels use, lane by lane."""
    from kernels.context import expanded_source

    ctx, queue = device_context()
    src = expanded_source("lanes") + """
    __kernel void draw8(__global const uint *c, const uint k0, const uint k1, __global uint *out) {
        const size_t g = get_global_id(0);
        uint8 c0 = vload8(0, c + 32 * g), c1 = vload8(0, c + 32 * g + 8);
        uint8 c2 = vload8(0, c + 32 * g + 16), c3 = vload8(0, c + 32 * g + 24);
        PHILOX8_10(c0, c1, c2, c3, k0, k1);
        vstore8(c0, 0, out + 32 * g); vstore8(c1, 0, out + 32 * g + 8);
        vstore8(c2, 0, out + 32 * g + 16); vstore8(c3, 0, out + 32 * g + 24);
    }"""
    prg = cl.Program(ctx, src).build()
    counters = rng.integers(0, 2**32, size=(512, 4), dtype=np.uint64).astype(np.uint32)
    counters[:3] = [c for c, _, _ in KAT]
    planar = np.ascontiguousarray(counters.reshape(64, 8, 4).transpose(0, 2, 1))  # (group, word, lane)
    buf = cl.Buffer(ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=planar)
    out = np.empty_like(planar)
    out_buf = cl.Buffer(ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    cl.Kernel(prg, "draw8")(queue, (64,), None, buf, np.uint32(5), np.uint32(0xFFFFFFFF), out_buf)
    cl.enqueue_copy(queue, out, out_buf)
    got = out.transpose(0, 2, 1).reshape(512, 4)
    np.testing.assert_array_equal(got, philox4x32_10(counters, (5, 0xFFFFFFFF)))
