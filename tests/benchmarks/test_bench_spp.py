"""``loom bench spp``: the decision rule and the FLIP measure on inputs with known answers, and a tiny real
run in which the reference compared with itself gives no error."""
from __future__ import annotations

import numpy as np
import pytest

from pipeline.benchmarks.spp import flip_mean, run, shown, smallest_invisible_spp


def _rows(d: dict[int, list[float]]) -> list[dict]:
    return [dict(frame=f, spp=s, d_aqm=v) for s, values in d.items() for f, v in enumerate(values)]


def test_smallest_invisible_spp_takes_the_worst_frame_and_every_larger_spp():
    rows = _rows({1: [9.0, 7.0], 2: [4.0, 2.5], 4: [1.0, 3.5], 8: [0.5, 2.0], 16: [0.2, 0.9]})
    assert smallest_invisible_spp(rows, 3.0) == 8  # 4 spp passes on frame 0, not on frame 1
    assert smallest_invisible_spp(rows, 4.0) == 2
    assert smallest_invisible_spp(rows, 0.1) is None
    # a larger spp above the threshold (noise) rules out the smaller ones below it
    rows = _rows({1: [2.0], 2: [4.0], 4: [1.0]})
    assert smallest_invisible_spp(rows, 3.0) == 4


def test_flip_is_zero_for_equal_images_and_grows_with_a_stair_stepped_edge():
    x = np.linspace(0.0, 1.0, 64)
    edge = np.clip((x[None, :] - x[:, None]) * 8.0 + 0.5, 0.0, 1.0)  # a smooth diagonal edge
    ref = np.repeat(edge[..., None], 3, axis=2)
    stairs = np.repeat((edge > 0.5).astype(float)[..., None], 3, axis=2)  # the same edge at one sample a pixel
    half = 0.5 * (ref + stairs)
    assert flip_mean(ref, ref, 30.0) == 0.0
    assert 0.0 < flip_mean(half, ref, 30.0) < flip_mean(stairs, ref, 30.0)


def test_shown_is_the_png_look_in_unit_range():
    rgb = np.array([[[0.0, 0.05, 10.0]]])
    out = shown(rgb, 0.05)
    assert out.shape == rgb.shape and out.min() == 0.0 and out.max() <= 1.0 and 0.0 < out[0, 0, 1] < out[0, 0, 2]


@pytest.mark.timeout(600)
def test_tiny_room_run_compares_every_spp_and_the_reference_with_itself_is_exact(tmp_path):
    result = run((68,), spps=(1, 4), reference_spp=4, photons=5_000, fmax=2, width=40, height=30,
                 store=str(tmp_path), echo=lambda s: None)
    rows = {r["spp"]: r for r in result["rows"]}
    assert set(rows) == {1, 4}
    assert rows[4]["flip"] == 0.0 and rows[4]["d_aqm"] == 0.0 and rows[4]["rel_rms"] == 0.0
    assert rows[1]["flip"] > 0.0 and rows[1]["rel_rms"] > 0.0
    (floor,) = result["reference_floor"]  # another seed: not the same bits
    assert floor["spp"] == 4 and floor["flip"] > 0.0
