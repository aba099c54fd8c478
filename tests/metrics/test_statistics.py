"""Confidence intervals over episodes and the paired test between estimators (issue 39, item 6)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from fkn_bench.metrics.statistics import ALPHA, mean_interval, paired_test


def test_student_t_interval_of_the_mean() -> None:
    values = [1.0, 2.0, 3.0, 4.0]
    interval = mean_interval(values)
    half = stats.t.ppf(0.975, 3) * np.std(values, ddof=1) / 2.0
    assert interval is not None and interval.runs == 4
    assert interval.mean == pytest.approx(2.5)
    assert (interval.low, interval.high) == pytest.approx((2.5 - half, 2.5 + half))
    assert interval.half_width == pytest.approx(half)
    wider = mean_interval(values, confidence=0.99)
    assert wider is not None and wider.half_width > interval.half_width


def test_a_known_interval() -> None:
    """mean 10, s = 2, n = 16: 10 +- 2.131 * 0.5 (t(0.975, 15) = 2.1314)."""
    values = 10.0 + 2.0 * np.array([1.0, -1.0] * 8) * math.sqrt(15 / 16)
    interval = mean_interval(values)
    assert interval is not None and interval.half_width == pytest.approx(1.0657, abs=1e-3)


@pytest.mark.parametrize("values", [[1.0], [], [1.0, np.nan, 2.0], [1.0, np.inf, 2.0]])
def test_no_interval_from_one_episode_or_a_non_finite_score(values: list[float]) -> None:
    """A diverged episode gives no interval (not a NaN one, not one over the other episodes)."""
    assert mean_interval(values) is None


def test_bad_confidence_is_refused() -> None:
    with pytest.raises(ValueError, match="confidence"):
        mean_interval([1.0, 2.0], confidence=1.0)


def test_paired_test_separates_a_consistent_difference() -> None:
    rng = np.random.default_rng(0)
    base = rng.uniform(0.01, 0.02, 20)
    worse = {s: v + 0.001 + 1e-5 * s for s, v in enumerate(base)}  # worse on every episode
    result = paired_test(dict(enumerate(base)), worse)
    assert result.episodes == 20 and not result.tied
    assert result.pvalue is not None and result.pvalue < 1e-4


def test_paired_test_ties_what_it_cannot_separate() -> None:
    rng = np.random.default_rng(1)
    base = rng.uniform(0.01, 0.02, 20)
    noisy = {s: v + (1e-4 if s % 2 else -1e-4) * (1 + 0.01 * s) for s, v in enumerate(base)}
    result = paired_test(dict(enumerate(base)), noisy)
    assert result.tied and result.pvalue is not None and result.pvalue >= ALPHA
    assert result.pvalue == pytest.approx(stats.wilcoxon(base - np.array(list(noisy.values()))).pvalue)


def test_paired_test_pairs_by_seed_over_the_common_seeds() -> None:
    first = {0: 1.0, 1: 2.0, 2: 3.0, 7: 100.0}
    second = {2: 3.5, 1: 2.5, 0: 1.5, 9: -100.0}
    result = paired_test(first, second)
    assert result.episodes == 3 and result.tied  # three episodes cannot reach 5% (exact p = 0.25)
    assert result.pvalue == pytest.approx(0.25)


def test_identical_scores_are_tied_and_no_common_seed_is_no_test() -> None:
    same = {0: 1.0, 1: 2.0}
    assert paired_test(same, dict(same)) == paired_test(same, dict(same))
    assert paired_test(same, dict(same)).tied and paired_test(same, dict(same)).pvalue == 1.0
    untested = paired_test({0: 1.0}, {1: 1.0})
    assert untested.pvalue is None and not untested.tied and untested.episodes == 0


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_a_non_finite_score_is_no_test_and_no_tie(bad: float) -> None:
    result = paired_test({0: 1.0, 1: bad, 2: 3.0}, {0: 1.1, 1: 2.0, 2: 3.1})
    assert result.pvalue is None and not result.tied and result.episodes == 3
