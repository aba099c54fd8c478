"""Summaries over seeds."""

from __future__ import annotations

import numpy as np
import pytest

from fkn_bench.metrics import SUMMARY_FIELDS, summarize


def test_mean_median_iqr() -> None:
    s = summarize([1.0, 2.0, 3.0, 4.0, 100.0])
    assert s.mean == pytest.approx(22.0)
    assert s.median == 3.0
    assert (s.q25, s.q75, s.iqr) == (2.0, 4.0, 2.0)
    assert (s.runs, s.missing) == (5, 0)
    assert tuple(s.as_dict()) == SUMMARY_FIELDS


def test_non_finite_runs_are_counted_not_averaged() -> None:
    s = summarize([1.0, np.nan, 3.0, np.inf])
    assert s.mean == 2.0 and s.runs == 2 and s.missing == 2


def test_all_missing() -> None:
    s = summarize([np.nan])
    assert np.isnan(s.mean) and s.runs == 0 and s.missing == 1
