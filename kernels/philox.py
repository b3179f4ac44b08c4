"""Philox4x32-10 counter-based random numbers, the NumPy twin of ``kernels/philox.cl``.

Photon ``i`` of frame ``f`` draws its numbers for bounce ``d`` from the counter
(i_lo, i_hi, stream, 0) under the key (seed, f): the numbers depend only on those values, never on
batch boundaries, chunking or which worker traces the photon (Salmon et al., SC 2011).
"""
from __future__ import annotations

import numpy as np

M0, M1 = np.uint64(0xD2511F53), np.uint64(0xCD9E8D57)
W0, W1 = 0x9E3779B9, 0xBB67AE85
MASK32 = np.uint64(0xFFFFFFFF)
# Streams: emission draws use EMISSION_STREAM + j; bounce d uses stream d.
EMISSION_STREAM = 0xFFFF0000


def philox4x32_10(counter: np.ndarray, key: tuple[int, int]) -> np.ndarray:
    """(n, 4) uint32 counters -> (n, 4) uint32 random words under ``key`` = (k0, k1)."""
    c = counter.astype(np.uint64)
    c0, c1, c2, c3 = c[:, 0], c[:, 1], c[:, 2], c[:, 3]
    k0, k1 = int(key[0]) & 0xFFFFFFFF, int(key[1]) & 0xFFFFFFFF
    for r in range(10):
        if r > 0:
            k0, k1 = (k0 + W0) & 0xFFFFFFFF, (k1 + W1) & 0xFFFFFFFF
        p0 = M0 * c0
        p1 = M1 * c2
        hi0, lo0 = p0 >> np.uint64(32), p0 & MASK32
        hi1, lo1 = p1 >> np.uint64(32), p1 & MASK32
        c0, c1, c2, c3 = hi1 ^ c1 ^ np.uint64(k0), lo1, hi0 ^ c3 ^ np.uint64(k1), lo0
    return np.stack([c0, c1, c2, c3], axis=1).astype(np.uint32)


def uniforms(photon: np.ndarray, stream: int, key: tuple[int, int]) -> np.ndarray:
    """(n, 4) doubles in [0, 1) for photons ``photon`` (int64 indices) on ``stream``."""
    photon = np.asarray(photon, dtype=np.uint64)
    counter = np.stack([photon & MASK32, photon >> np.uint64(32),
                        np.full(len(photon), stream, np.uint64), np.zeros(len(photon), np.uint64)], 1)
    words = philox4x32_10(counter, key)
    return (words >> np.uint32(8)).astype(np.float64) * (1.0 / 16777216.0)
