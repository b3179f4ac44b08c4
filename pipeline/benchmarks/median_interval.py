"""A distribution-free confidence interval of a median, from order statistics.

Why: ``loom bench render --repeat N`` reports the median of N pair ratios on a shared machine where
identical pairs move 1.5-2.1x; a median alone cannot say whether a target such as 1.8x is met or
only touched. For n independent samples of any continuous distribution, the interval between the
k-th smallest and the k-th largest sample holds the true median with probability
1 - 2 P(B <= k - 1), B ~ Binomial(n, 1/2) (the sign-test interval; e.g. Conover, *Practical
Nonparametric Statistics*, 3rd ed., §3.2). This picks the narrowest such interval whose coverage is
at least ``confidence``; fewer than 6 samples never reach 95 %, and then the whole range is
returned with its own (lower) coverage.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from math import comb


@dataclass(frozen=True)
class MedianInterval:
    low: float
    high: float
    coverage: float  # probability that [low, high] holds the true median (exact, not nominal)
    n: int


def median_interval(values: Iterable[float], confidence: float = 0.95) -> MedianInterval:
    """The order-statistics interval of the median of ``values`` (see the module docstring)."""
    xs = sorted(float(v) for v in values)
    n = len(xs)
    if n == 0:
        raise ValueError("no values")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    # k = 1 (the whole range) always; then the largest k whose coverage 1 - 2 P(B <= k - 1) holds
    below = 1 / 2**n  # P(B <= 0)
    best, coverage = 1, 1.0 - 2.0 * below
    for k in range(2, n // 2 + 1):
        below += comb(n, k - 1) / 2**n
        if 1.0 - 2.0 * below < confidence:
            break
        best, coverage = k, 1.0 - 2.0 * below
    return MedianInterval(xs[best - 1], xs[n - best], coverage, n)
