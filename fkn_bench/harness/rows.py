"""Tidy result rows: one row per estimator x scenario x seed x metric, grouped by ``group``.

Columns (:data:`COLUMNS`): ``estimator``, ``scenario``, ``seed``, ``group``, ``metric``,
``value`` (float; flags are 0/1) and ``unit``. Groups and metrics:

================  =====================================================================
group             metrics
================  =====================================================================
``state``         ``rmse`` (13-state RMSE, the primary score), ``rmse_qw`` ... ``rmse_vz``
``attitude``,     ``rmse``, ``median``, ``p95``, ``max`` of the group error magnitude
``position``,     (deg, m, rad/s, m/s) over the scored window; ``settling_time`` (s),
``omega``,        ``settled`` (0/1) and ``settling_band`` (the band used)
``velocity``
``settling``      ``time`` (s, the latest group settling time), ``settled`` (all groups)
``consistency``   ``nees_mean``, ``nis_mean``, ``nis_count``
``stability``     ``diverged``, ``non_finite``, ``cholesky_failed``, ``error_growth``,
                  ``nees_high``, ``failed`` (the estimator raised; counts as diverged)
``cost``          ``us_per_step_batched``, ``us_per_step_online``, ``peak_memory_mib``
================  =====================================================================

The ``cost`` group is measured, not computed: it differs between runs and is excluded from
determinism comparisons and from the CSV of record (:func:`deterministic_rows`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from fkn_bench.metrics import DIVERGENCE_REASONS, GROUP_UNITS, GROUPS, MAGNITUDE_STATISTICS, RunScores
from fkn_bench.types import STATE_NAMES, STATE_UNITS

__all__ = [
    "COLUMNS",
    "GROUP_ORDER",
    "NONDETERMINISTIC_GROUPS",
    "COST_METRICS",
    "score_rows",
    "cost_rows",
    "failure_rows",
    "deterministic_rows",
    "sort_rows",
]

COLUMNS: tuple[str, ...] = ("estimator", "scenario", "seed", "group", "metric", "value", "unit")
GROUP_ORDER: tuple[str, ...] = ("state", *GROUPS, "settling", "consistency", "stability", "cost")
NONDETERMINISTIC_GROUPS: tuple[str, ...] = ("cost",)
COST_METRICS: dict[str, str] = {
    "us_per_step_batched": "us",
    "us_per_step_online": "us",
    "peak_memory_mib": "MiB",
}

_Row = tuple[str, str, int, str, str, float, str]


def _frame(rows: list[_Row]) -> pd.DataFrame:
    frame = pd.DataFrame(rows, columns=list(COLUMNS))
    frame["seed"] = frame["seed"].astype(np.int64)
    frame["value"] = frame["value"].astype(np.float64)
    return frame


def score_rows(estimator: str, scenario: str, seeds: Sequence[int], scores: RunScores) -> pd.DataFrame:
    """Rows of every metric in ``scores`` (run ``i`` is seed ``seeds[i]``)."""
    if len(seeds) != scores.batch_size:
        raise ValueError(f"{len(seeds)} seeds for {scores.batch_size} runs")
    flags = scores.divergence.as_dict()
    rows: list[_Row] = []
    for i, seed in enumerate(int(s) for s in seeds):
        def add(group: str, metric: str, value: float, unit: str) -> None:
            rows.append((estimator, scenario, seed, group, metric, float(value), unit))

        add("state", "rmse", scores.state_rmse[i], "mixed")
        for j, (name, unit) in enumerate(zip(STATE_NAMES, STATE_UNITS)):
            add("state", f"rmse_{name}", scores.component_rmse[i, j], unit)
        for group in GROUPS:
            unit = GROUP_UNITS[group]
            for statistic in MAGNITUDE_STATISTICS:
                add(group, statistic, scores.group_statistics[group][statistic][i], unit)
            settling = scores.settling[group]
            add(group, "settling_time", settling.time[i], "s")
            add(group, "settled", settling.settled[i], "1")
            add(group, "settling_band", settling.band[i], unit)
        add("settling", "time", scores.settling_time[i], "s")
        add("settling", "settled", scores.settled[i], "1")
        for metric in ("nees_mean", "nis_mean", "nis_count"):
            add("consistency", metric, getattr(scores, metric)[i], "1")
        for flag in ("diverged", *DIVERGENCE_REASONS):
            add("stability", flag, flags[flag][i], "1")
        add("stability", "failed", 0.0, "1")
    return _frame(rows)


def cost_rows(estimator: str, scenario: str, seeds: Sequence[int], cost: Mapping[str, float]) -> pd.DataFrame:
    """The cell's cost measurements (:data:`COST_METRICS`), repeated for each of its seeds."""
    return _frame([(estimator, scenario, int(seed), "cost", metric, float(cost.get(metric, np.nan)), unit)
                   for seed in seeds for metric, unit in COST_METRICS.items()])


def failure_rows(estimator: str, scenario: str, seeds: Sequence[int]) -> pd.DataFrame:
    """Rows of a cell whose estimator raised: each seed diverged and failed, nothing else."""
    return _frame([(estimator, scenario, int(seed), "stability", flag, 1.0, "1")
                   for seed in seeds for flag in ("diverged", "failed")])


def sort_rows(rows: pd.DataFrame) -> pd.DataFrame:
    """Rows in a canonical order: estimator, scenario, seed, group (:data:`GROUP_ORDER`), metric."""
    order = {g: i for i, g in enumerate(GROUP_ORDER)}
    key = rows["group"].map(lambda g: order.get(g, len(order)))
    return (
        rows.assign(_group_order=key)
        .sort_values(["estimator", "scenario", "seed", "_group_order", "metric"], kind="mergesort")
        .drop(columns="_group_order")
        .reset_index(drop=True)
    )


def deterministic_rows(rows: pd.DataFrame) -> pd.DataFrame:
    """The rows that the same seeds reproduce exactly (every group but ``cost``), sorted."""
    return sort_rows(rows[~rows["group"].isin(NONDETERMINISTIC_GROUPS)])
