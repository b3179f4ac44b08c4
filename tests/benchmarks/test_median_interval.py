"""The order-statistics interval of a median (pipeline/benchmarks/median_interval.py): known answers
from the binomial distribution, and its coverage on samples of a known median."""
from __future__ import annotations

import numpy as np
import pytest

from pipeline.benchmarks.median_interval import median_interval


def test_eleven_samples_give_the_second_smallest_and_second_largest():
    # P(B <= 1) = 12 / 2048 for B ~ Bin(11, 1/2): coverage 1 - 24/2048 = 0.98828; the next, k = 3,
    # covers 1 - 134/2048 = 0.93457 < 0.95
    pairs = [1.99, 1.70, 1.77, 1.78, 1.64, 1.73, 1.76, 1.92, 1.99, 1.96, 1.71]
    got = median_interval(pairs)
    assert (got.low, got.high, got.n) == (1.70, 1.99, 11)
    assert got.coverage == pytest.approx(1 - 24 / 2048)
    at_90 = median_interval(pairs, confidence=0.90)
    assert (at_90.low, at_90.high) == (1.71, 1.96) and at_90.coverage == pytest.approx(1 - 134 / 2048)


@pytest.mark.parametrize("n, k", [(6, 1), (9, 2), (20, 6), (100, 40)])
def test_the_interval_is_the_narrowest_with_enough_coverage(n, k):
    # k from the binomial tables: the largest k with 1 - 2 P(B <= k - 1) >= 0.95 (n = 100: the 40th
    # to the 61st sample, the textbook interval)
    got = median_interval(range(1, n + 1))
    assert (got.low, got.high) == (k, n + 1 - k)
    assert got.coverage >= 0.95


def test_too_few_samples_return_the_range_with_its_own_coverage():
    got = median_interval([3.0, 1.0, 2.0])
    assert (got.low, got.high) == (1.0, 3.0) and got.coverage == pytest.approx(0.75)


def test_coverage_holds_on_samples_of_a_known_median():
    rng = np.random.default_rng(5)
    for n in (7, 11, 25):
        trials = 4000
        inside = 0
        for _ in range(trials):
            s = median_interval(rng.lognormal(0.0, 0.5, n))  # true median exp(0) = 1
            inside += s.low <= 1.0 <= s.high
        want = median_interval(range(n)).coverage
        assert abs(inside / trials - want) < 4 * np.sqrt(want * (1 - want) / trials), (n, inside / trials, want)


def test_bad_input_is_refused():
    with pytest.raises(ValueError):
        median_interval([])
    with pytest.raises(ValueError):
        median_interval([1.0], confidence=1.0)
