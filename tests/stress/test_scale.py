"""Light power scaled by 1e-30 ... 1e+30 scales every frame by the same factor
(docs/14-robustness.md §4): no NaN, Inf, flush to zero or overflow anywhere from the emitters through the
photon store, the temporal gather, the filter and the compositor to the float32 EXR.

Every light (point, spot and an emissive panel) of a closed room is scaled by s; the photons take
the same paths (emitter choice is by relative power), so frame(s) / s equals frame(1) to float32
rounding: within 1e-6 relative in every pixel of every layer, and zero exactly where frame(1) is
zero. Half-float EXRs gave +Inf at 1e10 and zeros at 1e-10 (pipeline/frames/images.py writes float32).
"""
from __future__ import annotations

import numpy as np
import pytest

from pipeline.frames.images import EXR_CHANNELS, frame_paths, read_exr
from pipeline.frames.settings import RenderSettings
from pipeline.run.render import RenderRequest, render
from tests.stress.scenes import lit_room

FRAMES = 3
SETTINGS = RenderSettings(width=40, height=30, spp=2)


def _render(tmp, scale: float):
    out = tmp / f"out{scale:g}"
    scene = lit_room(tmp / f"room{scale:g}.glb", scale=scale, frames=FRAMES)
    render(RenderRequest(scene_path=scene, frames=f"1-{FRAMES}", out_dir=out, n_photons=20_000, settings=SETTINGS),
           scheduler="synchronous")
    return [read_exr(frame_paths(out, f)[0])[0] for f in range(1, FRAMES + 1)]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    return _render(tmp_path_factory.mktemp("scale"), 1.0)


def _assert_scaled(frames, reference, scale):
    for frame, ref in zip(frames, reference):
        for name in EXR_CHANNELS:
            if name == "A" or name.startswith("albedo"):
                np.testing.assert_array_equal(frame[name], ref[name])
                continue
            got, want = frame[name].astype(np.float64), ref[name].astype(np.float64)
            assert np.isfinite(got).all(), name
            np.testing.assert_array_equal(got == 0, want == 0, err_msg=name)
            # float32 rounding of s x value, a few steps of 6e-8 (measured: at most 2.8e-7)
            np.testing.assert_allclose(got / scale, want, rtol=1e-6, atol=0, err_msg=name)
            assert (want > 0).mean() > 0.99  # the room is lit everywhere, directly and indirectly


@pytest.mark.parametrize("scale", [1e-30, 1e30, 1e-10, 1e10])
def test_frames_scale_with_light_power(tmp_path, reference, scale):
    _assert_scaled(_render(tmp_path, scale), reference, scale)
