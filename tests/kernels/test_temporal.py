"""Temporal windows (Condition (1), §5.1): the PoCL kernel equals its NumPy twin exactly, on random
and adversarial count tables, and the windows behave as the paper describes."""
from __future__ import annotations

import numpy as np
import pytest

from kernels.temporal import windows_cl, windows_reference
from tests.kernels.twin_base import KernelTwinTests

MODES = ("adaptive", "fixed", "off")


def both(counts, n, **kw):
    a = windows_cl(counts, n, **kw)
    b = windows_reference(counts, n, **kw)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    return a


def poisson_table(rng, frames, elements, scale=4.0):
    lam = rng.gamma(0.7, scale, elements)
    return rng.poisson(np.broadcast_to(lam, (frames, elements))).astype(np.uint32)


def _random_table(rng):
    """50 frames x 700 elements; some elements change lighting half-way, N_frame doubles at 30."""
    counts = poisson_table(rng, 50, 700)
    counts[25:, :200] *= 3
    n = np.full(50, 40_000.0)
    n[30:] = 80_000.0
    counts[30:] *= 2
    return counts, n


def _adversarial_table(rng, name):
    return {
        "all zero": lambda: np.zeros((12, 50), np.uint32),
        "one frame": lambda: poisson_table(rng, 1, 50),
        "near 2^31": lambda: (np.uint32(2**31 - 5) - rng.integers(0, 3, (12, 50))).astype(np.uint32),
        "max u32": lambda: np.full((12, 50), 2**32 - 1, np.uint32),
        "never hit": lambda: np.concatenate([poisson_table(rng, 12, 25), np.zeros((12, 25), np.uint32)], 1),
        "no elements": lambda: np.zeros((12, 0), np.uint32),
        "one element": lambda: poisson_table(rng, 12, 1),
    }[name]()


ADVERSARIAL = ("all zero", "one frame", "near 2^31", "max u32", "never hit", "no elements", "one element")


class TestWindowsTwin(KernelTwinTests):
    """``windows`` (temporal.cl) against :func:`windows_reference`: back and fwd to the bit."""

    # (table, keyword arguments of windows_cl)
    cases = {**{f"random-{mode}-fmax{fmax}-k{k}": ("random", dict(mode=mode, fmax=fmax, k_sigma=k))
                for mode in MODES for fmax, k in ((30, 2.0), (7, 1.0), (44, 3.0))},
             **{f"random-{mode}-subrange": ("random", dict(mode=mode, fmax=30, smoothing_frames=5, min_extent=4,
                                                           frames=(10, 20))) for mode in MODES},
             **{f"{name}-{mode}-fmax{fmax}": (name, dict(mode=mode, fmax=fmax))
                for name in ADVERSARIAL for mode in MODES for fmax in (0, 30, 500)},
             "random-adaptive-extent7-k3": ("random", dict(fmax=30, min_extent=7, k_sigma=3.0, frames=(0, 50))),
             "flicker-extent5": ("flicker", dict(fmax=12, smoothing_frames=1, min_extent=5)),
             # lighting steps between frames, scattered over elements: the means stop at them
             **{f"random-adaptive-cuts-s{s}": ("random-cuts", dict(fmax=30, smoothing_frames=s)) for s in (3, 5)},
             "one-frame-cuts": ("one-frame-cuts", dict(fmax=30))}

    def make_inputs(self, rng, case):
        name, kw = case
        if name == "random":
            counts, n = _random_table(rng)
        elif name == "random-cuts":
            counts, n = _random_table(rng)
            kw = {**kw, "cuts": rng.random((counts.shape[0] - 1, counts.shape[1])) < 0.1}
        elif name == "one-frame-cuts":
            counts, n = poisson_table(rng, 1, 50), np.full(1, 1000.0)
            kw = {**kw, "cuts": np.zeros((0, 50), bool)}
        elif name == "flicker":  # every neighbour fails Condition (1): the minimal extent everywhere
            counts = poisson_table(rng, 30, 200, scale=50.0)
            counts[::2] *= 5
            n = np.where(np.arange(30) % 3 == 0, 2e4, 1e4)
        else:
            counts = _adversarial_table(rng, name)
            n = np.full(counts.shape[0], 1000.0)
        return counts, n, kw

    def device(self, counts, n, kw):
        return windows_cl(counts, n, **kw)

    def twin(self, counts, n, kw):
        return windows_reference(counts, n, **kw)


@pytest.mark.parametrize("mode", MODES)
def test02_windows_stay_inside_fmax_and_the_animation(rng, mode):
    for name in ADVERSARIAL:
        counts = _adversarial_table(rng, name)
        for fmax in (0, 2, 30, 500):  # 500: F_max far longer than the animation
            back, fwd = windows_reference(counts, np.full(counts.shape[0], 1000.0), fmax=fmax, mode=mode)
            f = np.arange(counts.shape[0])[:, None]
            assert (back <= np.minimum(fmax // 2, f)).all(), name
            assert (fwd <= np.minimum(fmax // 2, counts.shape[0] - 1 - f)).all(), name


def test03_static_lighting_collects_everything_and_zero_counts_pass():
    counts = np.zeros((40, 3), np.uint32)
    counts[:, 1] = 100  # constant count: x == mu
    back, fwd = both(counts, np.full(40, 1e4), fmax=30)
    f = np.arange(40)[:, None]
    np.testing.assert_array_equal(back, np.broadcast_to(np.minimum(15, f), back.shape))
    np.testing.assert_array_equal(fwd, np.broadcast_to(np.minimum(15, 39 - f), fwd.shape))


def test04_a_step_stops_the_walk_in_one_direction_only():
    counts = np.full((41, 1), 100, np.uint32)
    counts[26:] = 200  # lighting doubles at frame 26: far outside 100 +- 2 * 10
    back, fwd = both(counts, np.full(41, 1e4), fmax=30)
    # Frame 20: mu = 100; x at 25 is (100+100+200)/3 = 133 > 120: forward stops after frame 24
    assert fwd[20, 0] == 4 and back[20, 0] == 15
    # Fixed mode collects the invalid photons anyway (Fig. 3b)
    back_f, fwd_f = both(counts, np.full(41, 1e4), fmax=30, mode="fixed")
    assert fwd_f[20, 0] == 15


def test04b_a_step_given_as_a_cut_keeps_the_means_to_its_sides():
    counts = np.full((41, 1), 100, np.uint32)
    counts[26:] = 300  # lighting triples at frame 26
    cuts = np.zeros((40, 1), bool)
    cuts[25] = True  # the step, as the regional step test reports it: between frames 25 and 26
    back, fwd = both(counts, np.full(41, 1e4), fmax=30)
    # Without the cut, mu at 25 and 26 mixes one frame of the other side: (100+100+300)/3 = 167 and
    # (100+300+300)/3 = 233, outside 2 sigma of every frame of its own side, so both walks stop at once
    assert (back[25, 0], fwd[25, 0]) == (1, 1) and (back[26, 0], fwd[26, 0]) == (1, 1)
    back_c, fwd_c = both(counts, np.full(41, 1e4), fmax=30, cuts=cuts)
    # With it, frame 25's mean is that of 24-25 and 26's of 26-27: each walks its own side to F_max/2
    # (the walk across the step is the caller's to cut: pipeline/collection/regional_steps.py)
    assert back_c[25, 0] == 15 and fwd_c[26, 0] == 14
    # Away from the step the windows do not change
    assert (back_c[:24] == back[:24]).all() and (fwd_c[28:] == fwd[28:]).all()


def test04c_cuts_must_match_the_table():
    with pytest.raises(ValueError, match="cuts"):
        windows_cl(np.ones((5, 2), np.uint32), np.ones(5), fmax=4, cuts=np.zeros((5, 2), bool))


def test05_min_extent_is_always_taken():
    counts = np.zeros((20, 1), np.uint32)
    counts[::2] = 1000  # flickers wildly: every neighbour fails Condition (1)
    counts[1::2] = 0
    n = np.full(20, 1e4)
    # Centred placement: (min_extent - 1) // 2 back, the rest forward, clipped at the ends
    back, fwd = both(counts, n, fmax=30, smoothing_frames=1)
    assert (back[1:-1] == 1).all() and (fwd[1:-1] == 1).all()
    assert back[0, 0] == 0 and fwd[0, 0] == 1 and back[-1, 0] == 1 and fwd[-1, 0] == 0
    back5, fwd5 = both(counts, n, fmax=30, smoothing_frames=1, min_extent=6)
    assert back5[10, 0] == 2 and fwd5[10, 0] == 3
    back0, fwd0 = both(counts, n, fmax=0, smoothing_frames=1)  # capped by F_max/2
    assert (back0 == 0).all() and (fwd0 == 0).all()


def test06_counts_are_compared_on_a_common_photon_budget():
    # The element's lighting is constant, but N_frame doubles at frame 20 and so do its counts
    counts = np.full((40, 1), 50, np.uint32)
    counts[20:] = 100
    n = np.full(40, 1e4)
    n[20:] = 2e4
    back, fwd = both(counts, n, fmax=30)
    assert fwd[15, 0] == 15 and back[25, 0] == 15
    # Without the budget scaling the raw counts would look like a lighting change
    back_raw, fwd_raw = both(counts, np.full(40, 1e4), fmax=30)
    assert fwd_raw[15, 0] < 15


def test07_sigma_grows_for_frames_with_fewer_photons():
    # mu = 100 at frame 10 with N = 1e4; frames from 11 on shoot a quarter of the photons and
    # their scaled count is 100 * 1.3 = 130. sigma(g) = sqrt(100 * 4) = 20: 130 is inside 100 +- 40,
    # whereas with the same N everywhere (sigma = 10) it is outside 100 +- 20.
    counts = np.full((30, 1), 100, np.uint32)
    counts[11:] = 33  # 33 * 4 = 132 on frame 10's budget
    n = np.full(30, 1e4)
    n[11:] = 2500.0
    back, fwd = both(counts, n, fmax=30, smoothing_frames=1)
    assert fwd[10, 0] == 15
    counts_same = counts.copy()
    counts_same[11:] = 132
    back2, fwd2 = both(counts_same, np.full(30, 1e4), fmax=30, smoothing_frames=1)
    assert back2[10, 0] == 10
    assert fwd2[10, 0] == 1  # the walk stops; the centred minimal extent takes one frame forward


def test09_refuses_bad_input():
    counts = np.zeros((5, 3), np.uint32)
    with pytest.raises(ValueError, match="needs photons"):
        windows_cl(counts, [1, 1, 0, 1, 1], fmax=4)
    with pytest.raises(ValueError, match="temporal mode"):
        windows_cl(counts, np.ones(5), fmax=4, mode="sometimes")
    with pytest.raises(ValueError, match="F_max"):
        windows_cl(counts, np.ones(5), fmax=600)
    with pytest.raises(ValueError, match="frames"):
        windows_reference(counts, np.ones(5), fmax=4, frames=(2, 9))
