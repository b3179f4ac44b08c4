"""Camera rays (camera.cl) equal their NumPy twin and the compositor's own jitter and camera."""
from __future__ import annotations

import numpy as np
import pytest

from kernels.camera import camera_rays_cl, camera_rays_reference
from tests.kernels.twin_base import KernelTwinTests


def _rotation(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.array([1.0, 1.0, np.sign(np.linalg.det(q))])


class TestCameraTwin(KernelTwinTests):
    """``camera8`` against :func:`camera_rays_reference`: float32 directions within 2e-7."""

    # (first sample c0, count, spp): none, one, fewer than LANES, not a multiple of LANES x WORK_GROUP
    cases = {"empty": (0, 0, 1), "one": (0, 1, 1), "seven": (5, 7, 4), "63": (5, 63, 1),
             "513": (1000, 513, 4), "20000": (1000, 20_000, 1)}
    atol = 2e-7

    def make_inputs(self, rng, case):
        c0, count, spp = case
        return int(rng.integers(0, 2**63)), c0, count, spp, 320, 240, 0.9, _rotation(rng)

    def device(self, *args):
        return camera_rays_cl(*args)

    def twin(self, *args):
        return camera_rays_reference(*args)


@pytest.mark.parametrize("spp", [1, 4])
def test_directions_are_unit(rng, spp):
    d = camera_rays_reference(int(rng.integers(0, 2**63)), 3, 5000, spp, 320, 240, 0.9, _rotation(rng))
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-6)


def test_rays_follow_the_pinhole_camera():
    """The centre sample looks down -Z; the top and bottom rows are yfov apart; jitter stays
    inside each pixel."""
    yfov, width, height = 0.9, 200, 100
    rot = np.eye(3)
    mid = (height // 2) * width + width // 2
    d = camera_rays_reference(11, mid, 1, 1, width, height, yfov, rot)[0]
    assert np.arccos(-d[2]) < 2 * np.tan(yfov / 2) / height * 1.5  # within about a pixel of -Z
    top = camera_rays_reference(11, width // 2, 1, 1, width, height, yfov, rot)[0]
    bottom = camera_rays_reference(11, (height - 1) * width + width // 2, 1, 1, width, height, yfov, rot)[0]
    angle = np.arctan2(top[1], -top[2]) - np.arctan2(bottom[1], -bottom[2])
    assert abs(angle - yfov) < 2 * yfov / height
    a = camera_rays_reference(3, 0, 4, 4, width, height, yfov, rot)  # one pixel's four samples
    assert len(np.unique(a, axis=0)) == 4 and np.all(a[:, 0] < 0) and np.all(a[:, 1] > 0)
