"""Summaries over seeds of stored results (the run table that shows them: tests/reporting/test_report.py)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from fkn_bench.harness import ResultStore, build_grid, run_grid, summarize_pair, summarize_results
from fkn_bench.harness.sources import SimulatedSource
from fkn_bench.metrics import NEES_DOF, chi2_interval
from fkn_bench.reporting import summary_text
from fkn_bench.types import STATE_NAMES

JSON_KEYS = {
    "estimator", "scenario", "seeds", "rmse", "attitude_rmse_deg", "position_rmse_m", "omega_rmse_rad_s",
    "velocity_rmse_m_s", "settling_time_s", "diverged_fraction", "anees", "nees_in_bounds_fraction", "us_per_step",
}


def test_summary_of_stored_results(small_results_dir: Path) -> None:
    results = ResultStore(small_results_dir).load()
    assert len(results) == 8
    s = summarize_pair(results, "oracle-ekf", "ds1")
    assert JSON_KEYS <= set(s)
    assert s["seeds"] == list(range(12)) and s["runs"] == 12
    assert list(s["rmse"]) == list(STATE_NAMES)
    rows = results.rows
    per_seed = rows[(rows.estimator == "oracle-ekf") & (rows.scenario == "ds1") & (rows.group == "attitude")
                    & (rows.metric == "rmse")].value
    assert s["attitude_rmse_deg"] == pytest.approx(per_seed.mean(), rel=1e-12)
    assert s["statistics"]["attitude_rmse_deg"]["median"] == pytest.approx(per_seed.median(), rel=1e-12)
    assert s["anees_bounds"] == pytest.approx([float(b) for b in chi2_interval(NEES_DOF, 12)])
    assert 0.0 <= s["nees_in_bounds_fraction"] <= 1.0 and s["anees"] > 0
    assert s["diverged_fraction"] == 0.0 and s["errors"] == []


def test_pooled_anees_equals_the_mean_of_per_seed_nees(small_results_dir: Path) -> None:
    results = ResultStore(small_results_dir).load()
    nees, _ = results.pooled("manual-ekf", "ds2")
    rows = results.rows
    per_seed = rows[(rows.estimator == "manual-ekf") & (rows.scenario == "ds2") & (rows.metric == "nees_mean")].value
    assert np.sum(nees.sum) / np.sum(nees.count) == pytest.approx(per_seed.mean(), rel=1e-12)


def test_failed_runs_count_as_diverged(short_ds1: SimulatedSource, test_estimators: None) -> None:
    outcome = run_grid(build_grid(["raising", "nan"], [short_ds1], range(3)), progress=False)
    raising, nan = summarize_results(outcome.results, [("raising", "ds1"), ("nan", "ds1")])
    assert raising["diverged_fraction"] == 1.0 and raising["failed_runs"] == 3
    assert np.isnan(raising["state_rmse"]) and "boom" in raising["errors"][0]
    assert nan["diverged_fraction"] == 1.0 and nan["divergence_reasons"]["non_finite"] == 1.0
    text = summary_text([raising, nan])
    assert "Failures:" in text and "raising / ds1" in text


def test_a_seed_whose_score_is_not_finite_is_counted_not_dropped(short_ds1: SimulatedSource, test_estimators: None,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 34, finding 2: a seed with a NaN score left the mean silently; "2 seeds" was seed 1
    alone. The mean is still over the finite seeds (as for diverged ones), and the count shows."""
    from fkn_bench.estimators import Estimates, make_estimator, registry

    class FirstSeedNaN(type(make_estimator("nan"))):  # NaN estimates for the first seed of the batch only
        name = "first-nan"

        def estimate(self, measurements, mask, dt):  # noqa: ANN001, ANN202
            inner = make_estimator("manual-ekf").estimate(measurements, mask, dt)
            means = np.array(inner.means)
            means[0, 150:] = np.nan
            return Estimates(means=means, error_covariances=inner.error_covariances)

    registry.register_estimator("first-nan", lambda scenario=None, **_: FirstSeedNaN())
    outcome = run_grid(build_grid(["first-nan"], [short_ds1], range(2)), progress=False)
    (summary,) = summarize_results(outcome.results, [("first-nan", "ds1")])
    assert summary["runs"] == 2 and summary["non_finite_runs"] == 1 and summary["statistics"]["state_rmse"]["runs"] == 1
    assert np.isfinite(summary["state_rmse"]) and summary["diverged_fraction"] == 0.5
    text = summary_text([summary])
    assert re.search(r"first-nan / ds1 +2 \(1 not finite\) ", text)
    assert 'seeds "N (K not finite)": the 13-state RMSE of K of the N seeds is NaN or infinite' in text
    assert "not finite" not in summary_text([{**summary, "non_finite_runs": 0}])
