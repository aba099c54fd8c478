"""Summaries of a metric over runs (seeds): mean, median and interquartile range.

Only finite values enter a summary; how many runs were left out (non-finite values, e.g. of a
diverged run) is reported as ``missing``, so a divergence is never hidden inside an average.
Quartiles use linear interpolation (:func:`numpy.percentile` default).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fkn_bench.types import ArrayF

__all__ = ["Summary", "summarize", "SUMMARY_FIELDS"]

SUMMARY_FIELDS: tuple[str, ...] = ("mean", "median", "q25", "q75", "iqr", "runs", "missing")
"""Fields of :class:`Summary`, in table order."""


@dataclass(frozen=True)
class Summary:
    """Mean, median, quartiles and interquartile range of the finite values; ``runs`` counts
    them and ``missing`` the non-finite ones. All statistics are NaN when ``runs == 0``."""

    mean: float
    median: float
    q25: float
    q75: float
    runs: int
    missing: int

    @property
    def iqr(self) -> float:
        return self.q75 - self.q25

    def as_dict(self) -> dict[str, float | int]:
        return {name: getattr(self, name) for name in SUMMARY_FIELDS}


def summarize(values: Sequence[float] | ArrayF) -> Summary:
    """Summarise per-run values (any shape; flattened)."""
    values = np.asarray(values, dtype=np.float64).ravel()
    finite = values[np.isfinite(values)]
    missing = int(values.size - finite.size)
    if finite.size == 0:
        nan = float("nan")
        return Summary(nan, nan, nan, nan, 0, missing)
    q25, median, q75 = np.percentile(finite, [25.0, 50.0, 75.0])
    return Summary(float(np.mean(finite)), float(median), float(q25), float(q75), int(finite.size), missing)
