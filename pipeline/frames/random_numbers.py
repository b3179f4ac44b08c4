"""Counter-based random numbers of the compositor, and how its random dimensions are laid out.

Every random number is a hash of (seed, frame, pixel, sample, dimension) (splitmix64, Steele et
al., OOPSLA 2014), so pixels do not depend on chunking or workers. Dimensions per camera sample:
0 and 1 jitter the camera ray (kernels/camera.cl); from 2 on, :data:`DIMS_PER_DEPTH` per reflection
depth (the glossy lobe, 2, then the area-light samples, 3 each); sky samples from :data:`SKY_DIMS`
on, :data:`SKY_DIMS_PER_DEPTH` per depth (2 each, up to 256).
"""
from __future__ import annotations

import numpy as np

from kernels.camera import mix64

DIMS_PER_DEPTH = 16  # random dimensions per reflection depth: lobe (2) + area samples (3 each)
SKY_DIMS, SKY_DIMS_PER_DEPTH = 1 << 20, 512  # random dimensions of sky samples (2 each, up to 256)

_M64 = (1 << 64) - 1


def frame_key(seed: int, frame: int) -> int:
    """64-bit key of (seed, frame) for :func:`uniform`."""
    k = mix64(np.array([(seed * 0x9E3779B97F4A7C15 + 0x632BE59BD9B4E019) & _M64], np.uint64))
    return int(mix64(k ^ np.uint64(frame & _M64))[0])


def _hash(key: int, counter: np.ndarray, dim: int) -> np.ndarray:
    x = mix64(counter.astype(np.uint64) ^ np.uint64(key))
    return mix64(x + np.uint64((dim * 0x9E3779B97F4A7C15) & _M64))


def uniform(key: int, counter: np.ndarray, dim: int) -> np.ndarray:
    """float64 in [0, 1) for each counter (pixel x spp + sample) and a dimension number."""
    return (_hash(key, counter, dim) >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))
