"""``loom bench spp``: the decision rule and the FLIP measure on inputs with known answers, and a tiny real
run in which the reference compared with itself gives no error."""
from __future__ import annotations

import numpy as np
import pytest

from pipeline.benchmarks.error_measures import flip_mean, shown
from pipeline.benchmarks.spp import (
    adaptive_image,
    allot_extra,
    displayed_spread,
    run,
    smallest_invisible_spp,
)


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


def test_allot_extra_takes_the_largest_spreads_and_breaks_ties_in_pixel_order():
    spread = np.array([[0.0, 3.0, 1.0], [3.0, 0.0, 2.0]])
    assert allot_extra(spread, 0.5).tolist() == [[False, True, False], [True, False, True]]
    assert allot_extra(spread, 1 / 6).tolist() == [[False, True, False], [False, False, False]]  # tie: first pixel
    assert not allot_extra(spread, 0.0).any() and allot_extra(spread, 1.0).all()


def _edge_samples(rng, n: int, size: int = 32) -> np.ndarray:
    """n one-sample images (n, size, size, 3) of a black/white vertical edge at x = 10.5 pixels, jittered."""
    x = np.arange(size)[None, None, :] + rng.random((n, size, size))
    return np.repeat((x > 10.5).astype(float)[..., None], 3, axis=3)


def test_displayed_spread_is_zero_off_the_edge_and_the_edge_pixel_gets_the_samples(rng):
    first = _edge_samples(rng, 4)
    spread = displayed_spread(first, 0.18)
    near = np.isin(np.arange(32), (9, 10, 11))  # the edge column and its neighbours (3x3 neighbourhood)
    assert np.all(spread[:, ~near] == 0.0) and np.all(spread[:, 10] > 0.0)  # even where 4 samples agreed
    mask = allot_extra(spread, 3 / 32)
    assert mask[:, 10].all() and not mask[:, ~near].any()


def test_two_pass_image_beats_uniform_sampling_at_equal_samples_on_an_edge(rng):
    """Uniform 8 a pixel, or 4 then 28 more in the 3/32 of the pixels with the largest spread: 4 + 28 x 3/32
    = 6.6 samples a pixel on average, fewer, and still less error."""
    truth = np.repeat(np.where(np.arange(32) > 10, 1.0, 0.0)[None, :].repeat(32, 0)[..., None], 3, axis=2)
    truth[:, 10] = 0.5  # the edge pixel's covered share
    uniform = _edge_samples(rng, 8).mean(axis=0)
    first = _edge_samples(rng, 4)
    extra = _edge_samples(rng, 28).mean(axis=0)
    mask = allot_extra(displayed_spread(first, 0.18), 3 / 32)
    two_pass = adaptive_image(first, extra, 28, mask)
    err = lambda img: float(np.sqrt(np.mean((img - truth) ** 2)))  # noqa: E731
    assert err(two_pass) < 0.75 * err(uniform)
    assert np.array_equal(adaptive_image(first, extra, 28, np.zeros((32, 32), bool)), first.mean(axis=0))
