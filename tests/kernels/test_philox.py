"""Philox4x32-10: Random123's known answers, and the OpenCL version equals the NumPy one."""
from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest

from kernels.context import SOURCE_DIR, device_context, expanded_source
from kernels.philox import philox4x32_10, uniforms
from tests.kernels.twin_base import KernelTwinTests

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


def _counters(rng, n):
    """``n`` random (n, 4) uint32 counters, the known-answer ones first."""
    counters = rng.integers(0, 2**32, size=(n, 4), dtype=np.uint64).astype(np.uint32)
    k = min(n, len(KAT))
    counters[:k] = np.array([c for c, _, _ in KAT[:k]], np.uint32).reshape(k, 4)
    return counters


class TestPhiloxTwin(KernelTwinTests):
    """``philox4x32_10`` of philox.cl against :func:`philox4x32_10`, to the bit."""

    cases = {"0": (0, (0xDEADBEEF, 7)), "1": (1, (0, 0)), "3": (3, (0xFFFFFFFF, 0xFFFFFFFF)),
             "4097": (4097, (0xDEADBEEF, 7))}
    SOURCE = """
    #include "philox.cl"
    __kernel void draw(__global const uint4 *c, const uint k0, const uint k1, __global uint4 *out) {
        size_t i = get_global_id(0);
        out[i] = philox4x32_10(c[i], (uint2)(k0, k1));
    }"""

    def make_inputs(self, rng, case):
        n, key = case
        return _counters(rng, n), key

    def device(self, counters, key):
        out = np.empty_like(counters)
        if len(counters) == 0:
            return out
        ctx, queue = device_context()
        prg = cl.Program(ctx, self.SOURCE).build(options=["-I", str(SOURCE_DIR)])
        buf = cl.Buffer(ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=counters)
        out_buf = cl.Buffer(ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
        cl.Kernel(prg, "draw")(queue, (len(counters),), None, buf, np.uint32(key[0]), np.uint32(key[1]), out_buf)
        cl.enqueue_copy(queue, out, out_buf)
        return out

    def twin(self, counters, key):
        return philox4x32_10(counters, key)


def test_uniforms_are_uniform_and_in_range():
    u = uniforms(np.arange(200_000), 3, (1, 2))
    assert u.min() >= 0.0 and u.max() < 1.0
    hist, _ = np.histogram(u.ravel(), bins=20, range=(0, 1))
    expected = u.size / 20
    chi2 = ((hist - expected) ** 2 / expected).sum()
    assert chi2 < 45.3  # 99.9th percentile of chi-squared with 19 degrees of freedom
    assert not np.array_equal(uniforms(np.arange(10), 3, (1, 2)), uniforms(np.arange(10), 4, (1, 2)))


class TestEightLanePhiloxTwin(TestPhiloxTwin):
    """PHILOX8_10 (lanes.cl), what the emission and bounce kernels use, lane by lane; a count that
    is not a multiple of the 8 lanes is padded with zero counters."""

    cases = {"1": (1, (5, 0xFFFFFFFF)), "8": (8, (0, 0)), "13": (13, (5, 0xFFFFFFFF)),
             "512": (512, (5, 0xFFFFFFFF)), "517": (517, (0xDEADBEEF, 7))}
    SOURCE = """
    __kernel void draw8(__global const uint *c, const uint k0, const uint k1, __global uint *out) {
        const size_t g = get_global_id(0);
        uint8 c0 = vload8(0, c + 32 * g), c1 = vload8(0, c + 32 * g + 8);
        uint8 c2 = vload8(0, c + 32 * g + 16), c3 = vload8(0, c + 32 * g + 24);
        PHILOX8_10(c0, c1, c2, c3, k0, k1);
        vstore8(c0, 0, out + 32 * g); vstore8(c1, 0, out + 32 * g + 8);
        vstore8(c2, 0, out + 32 * g + 16); vstore8(c3, 0, out + 32 * g + 24);
    }"""

    def device(self, counters, key):
        n = len(counters)
        groups = -(-n // 8)
        padded = np.zeros((groups * 8, 4), np.uint32)
        padded[:n] = counters
        planar = np.ascontiguousarray(padded.reshape(groups, 8, 4).transpose(0, 2, 1))  # (group, word, lane)
        ctx, queue = device_context()
        prg = cl.Program(ctx, expanded_source("lanes") + self.SOURCE).build()
        buf = cl.Buffer(ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=planar)
        out = np.empty_like(planar)
        out_buf = cl.Buffer(ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
        cl.Kernel(prg, "draw8")(queue, (groups,), None, buf, np.uint32(key[0]), np.uint32(key[1]), out_buf)
        cl.enqueue_copy(queue, out, out_buf)
        return out.transpose(0, 2, 1).reshape(-1, 4)[:n]
