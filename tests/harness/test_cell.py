"""Running one cell: rows, sums, costs, and failures recorded instead of raised."""

from __future__ import annotations

import numpy as np
import pytest

from fkn_bench.harness import CellSpec, resolve_estimator, run_cell
from fkn_bench.harness.rows import COLUMNS, COST_METRICS, GROUP_ORDER
from fkn_bench.harness.sources import SimulatedSource
from fkn_bench.metrics import MetricSettings


def _spec(source: SimulatedSource, estimator: str, seeds: tuple[int, ...] = (0, 1, 2)) -> CellSpec:
    return CellSpec(resolve_estimator(estimator, source.scenario), source, seeds, MetricSettings(), online_steps=50)


def _value(rows, seed: int, group: str, metric: str) -> float:
    hit = rows[(rows.seed == seed) & (rows.group == group) & (rows.metric == metric)]
    assert len(hit) == 1
    return float(hit.value.iloc[0])


def test_cell_rows_and_sums(short_ds1: SimulatedSource) -> None:
    result = run_cell(_spec(short_ds1, "manual-ekf"))
    assert result.status == "ok" and result.error is None
    rows = result.rows
    assert tuple(rows.columns) == COLUMNS
    assert set(rows.group) == set(GROUP_ORDER)
    assert sorted(set(rows.seed)) == [0, 1, 2]
    assert len(rows) == 3 * len(rows[rows.seed == 0])
    assert (rows.estimator == "manual-ekf").all() and (rows.scenario == "ds1").all()
    assert 0.0 < _value(rows, 0, "state", "rmse") < 0.1
    assert _value(rows, 0, "stability", "diverged") == 0.0
    for metric in ("us_per_step_batched", "us_per_step_online"):
        assert _value(rows, 1, "cost", metric) > 0
    assert set(rows[rows.group == "cost"].metric) == set(COST_METRICS)
    assert result.nees is not None and result.nees.sum.shape == (100,)  # 200 steps - cut 100
    assert result.nees.count.tolist() == [3.0] * 100
    assert result.nis is not None and result.nis.count.max() == 3.0
    assert result.provenance["numpy"] == np.__version__


def test_raising_estimator_is_a_failed_cell(short_ds1: SimulatedSource, test_estimators: None) -> None:
    result = run_cell(_spec(short_ds1, "raising"))
    assert result.status == "failed"
    assert "RuntimeError: boom" in result.error and "Traceback" in result.notes["traceback"]
    assert result.nees is None
    for seed in (0, 1, 2):
        assert _value(result.rows, seed, "stability", "diverged") == 1.0
        assert _value(result.rows, seed, "stability", "failed") == 1.0
    assert np.isnan(result.rows[result.rows.group == "cost"].value).all()


def test_nan_estimates_diverge_and_online_failure_is_a_note(short_ds1: SimulatedSource,
                                                            test_estimators: None) -> None:
    result = run_cell(_spec(short_ds1, "nan"))
    assert result.status == "ok"
    assert _value(result.rows, 0, "stability", "non_finite") == 1.0
    assert _value(result.rows, 0, "stability", "diverged") == 1.0
    assert np.isnan(_value(result.rows, 0, "state", "rmse"))
    assert "boom" in result.notes["online_error"]
    assert np.isnan(_value(result.rows, 0, "cost", "us_per_step_online"))


def test_unknown_estimator_is_a_failed_cell(short_ds1: SimulatedSource) -> None:
    result = run_cell(_spec(short_ds1, "no-such-estimator"))
    assert result.status == "failed" and "no-such-estimator" in result.error


@pytest.mark.parametrize("estimator", ["manual-ukf", "manual-mekf"])
def test_other_variants_run(short_ds1: SimulatedSource, estimator: str) -> None:
    result = run_cell(_spec(short_ds1, estimator, seeds=(4,)))
    assert result.status == "ok" and _value(result.rows, 4, "state", "rmse") < 0.1
