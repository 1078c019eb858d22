"""The sweep's verdicts: intervals against their oracles (scipy's binomial, a simulated median),
and pass / FAIL / inconclusive from what a sample supports."""

from __future__ import annotations

import numpy as np

from tagloc.eval.tag_sweep_verdicts import median_interval, verdict


def test_the_median_interval_covers_the_median_as_often_as_it_says() -> None:
    rng = np.random.default_rng(0)
    n, trials, covered = 25, 2000, 0
    for _ in range(trials):
        lo, hi = median_interval(rng.exponential(1.0, n), confidence=0.95)
        covered += lo <= np.log(2.0) <= hi  # the exponential's median
    assert covered / trials >= 0.94


def test_four_views_give_their_range_and_no_values_give_everything() -> None:
    assert median_interval([3.0, 1.0, 4.0, 2.0]) == (1.0, 4.0)
    assert median_interval([]) == (-np.inf, np.inf)


def test_a_verdict_fails_only_when_the_interval_misses() -> None:
    assert verdict(True, False) is True
    assert verdict(False, True) is False
    assert verdict(False, False) is None
