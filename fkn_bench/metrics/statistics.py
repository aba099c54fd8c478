"""Statistics over test episodes (seeds): the confidence interval of a mean score and the paired
test between two estimators scored on the same episodes (what the leaderboards report).

Interval (:func:`mean_interval`): the Student-t interval of the mean over episodes,
``mean +- t(1 - alpha/2, n - 1) s / sqrt(n)`` with ``s`` the sample standard deviation
(``ddof=1``) and ``t`` the Student-t quantile (:func:`scipy.stats.t.ppf`); 95% by default
(:data:`CONFIDENCE`). Rules: the interval needs at least two episodes, and every score finite --
a diverged episode (NaN or infinite score) makes the mean over the finite ones no mean over the
episodes, so no interval is given (``None``; the leaderboards print ``n/a`` and count the
non-finite runs beside it) rather than a NaN or a too-narrow interval.

Paired test (:func:`paired_test`): the two-sided Wilcoxon signed-rank test (Wilcoxon 1945,
"Individual comparisons by ranking methods", Biometrics Bulletin 1(6)) on the per-episode
differences of the scores, over the episodes (seeds) both estimators were scored on
(:func:`scipy.stats.wilcoxon`, ``zero_method="wilcox"``: episodes with a zero difference are left
out; ``method="auto"``: the exact null distribution for up to 50 episodes without zero
differences, else the normal approximation). It makes no assumption of normality, which per-episode
RMSEs (skewed, bounded below by zero) do not meet. Two estimators are *tied* when the test cannot
separate them at the 5% level (``p >= ALPHA``). Rules: with no common episode, or a non-finite
score on a common episode, there is no test (``pvalue`` None) and no tie; when every difference
is zero the estimators are tied with ``p = 1``.

:mod:`scipy.stats` is imported on first use (it costs a noticeable fraction of a second).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from fkn_bench.types import ArrayF

__all__ = [
    "ALPHA",
    "CONFIDENCE",
    "INTERVAL_METHOD",
    "TEST_METHOD",
    "MeanInterval",
    "PairedTest",
    "mean_interval",
    "paired_test",
]

CONFIDENCE = 0.95
"""Confidence level of :func:`mean_interval`."""
ALPHA = 0.05
"""Significance level of :func:`paired_test`: estimators with ``p >= ALPHA`` are tied."""
INTERVAL_METHOD = "Student-t 95% confidence interval of the mean over test episodes (seeds)"
"""How the interval is computed, in words (for tables' notes)."""
TEST_METHOD = ("two-sided Wilcoxon signed-rank test on the per-episode differences over the episodes both "
               "estimators were scored on, at the 5% level")
"""How ties are decided, in words (for tables' notes)."""


@dataclass(frozen=True)
class MeanInterval:
    """The mean of ``runs`` episode scores and its confidence interval ``[low, high]``."""

    mean: float
    low: float
    high: float
    runs: int

    @property
    def half_width(self) -> float:
        """``high - mean`` (the interval is symmetric about the mean)."""
        return self.high - self.mean


@dataclass(frozen=True)
class PairedTest:
    """The outcome of :func:`paired_test`: ``pvalue`` (None: not tested, module rules), the number
    of common ``episodes``, and whether the two are ``tied`` (``p >= ALPHA``)."""

    pvalue: float | None
    episodes: int
    tied: bool


def mean_interval(values: Sequence[float] | ArrayF, confidence: float = CONFIDENCE) -> MeanInterval | None:
    """The Student-t interval of the mean of ``values`` (one score per episode), or None when
    there are fewer than two values or one is not finite (module docstring)."""
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence}")
    values = np.asarray(values, dtype=np.float64).ravel()
    if values.size < 2 or not np.all(np.isfinite(values)):
        return None
    from scipy import stats

    mean = float(np.mean(values))
    half = float(stats.t.ppf(0.5 + confidence / 2.0, values.size - 1)) * float(np.std(values, ddof=1)) / math.sqrt(values.size)
    if not math.isfinite(half):  # an overflowing spread (scores near the float limit)
        return None
    return MeanInterval(mean, mean - half, mean + half, int(values.size))


def paired_test(first: Mapping[int, float], second: Mapping[int, float], alpha: float = ALPHA) -> PairedTest:
    """The two-sided Wilcoxon signed-rank test of two estimators' scores ``{seed: score}`` over
    the seeds both have (module docstring)."""
    common = sorted(set(first) & set(second))
    a = np.asarray([first[s] for s in common], dtype=np.float64)
    b = np.asarray([second[s] for s in common], dtype=np.float64)
    if not common or not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        return PairedTest(None, len(common), False)
    differences = a - b
    if not np.all(np.isfinite(differences)):  # finite scores whose difference overflows
        return PairedTest(None, len(common), False)
    if not np.any(differences):
        return PairedTest(1.0, len(common), True)
    from scipy import stats

    pvalue = float(stats.wilcoxon(differences, zero_method="wilcox", alternative="two-sided", method="auto").pvalue)
    return PairedTest(pvalue, len(common), pvalue >= alpha)
