"""Summaries over seeds of one estimator on one scenario: what ``fkn-bench run`` prints and the
leaderboards rank.

Scalars are means over runs (seeds) of the per-run values, taken over the runs where the value is
finite (:func:`fkn_bench.metrics.summarize`); ``statistics`` adds median and interquartile range,
and how many runs each left out (``missing``). A run whose primary score (the 13-state RMSE) is
not finite, NaN or infinity (an estimate that diverged to NaN or overflowed, a failed run), is
never dropped without a word: ``non_finite_runs`` counts them, and the run table shows the count
beside the seeds. Divergence is reported apart (``diverged_fraction``, over all runs, failed runs
included) and never folded into the RMSEs. ANEES/ANIS pool every run's per-step NEES/NIS
(Bar-Shalom, Li & Kirubarajan 2001, sec. 5.4): ``anees`` is the average over runs and steps,
``nees_in_bounds_fraction`` the share of steps whose average over the runs lies in the two-sided
95% chi-square interval for that many runs (``anees_bounds``, given for all runs).

The primary score per seed is kept (``state_rmse_by_seed``, aligned with ``seeds``; NaN where not
finite) for the paired tests between estimators (:func:`fkn_bench.metrics.statistics.paired_test`),
and ``state_rmse_ci`` is its 95% Student-t interval of the mean over the seeds
(:func:`fkn_bench.metrics.statistics.mean_interval`): ``[low, high]``, or ``None`` when there are
fewer than two seeds or a seed's score is not finite (never a NaN interval).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from fkn_bench.harness.records import Results
from fkn_bench.metrics import DIVERGENCE_REASONS, GROUPS, LOST_TRACK_REASONS, NEES_DOF, NIS_DOF, average_statistic, chi2_interval, summarize
from fkn_bench.metrics.statistics import mean_interval
from fkn_bench.types import STATE_NAMES

__all__ = ["PRIMARY_SCORE", "GROUP_RMSE_KEYS", "STATISTIC_METRICS", "summarize_pair", "summarize_results",
           "per_seed_table"]

PRIMARY_SCORE = ("state", "rmse")
"""(group, metric) of the primary score: the 13-state RMSE (lower is better)."""

STATISTIC_METRICS: dict[str, tuple[str, str]] = {
    "state_rmse": ("state", "rmse"),
    "attitude_rmse_deg": ("attitude", "rmse"),
    "position_rmse_m": ("position", "rmse"),
    "omega_rmse_rad_s": ("omega", "rmse"),
    "velocity_rmse_m_s": ("velocity", "rmse"),
    "settling_time_s": ("settling", "time"),
    "nees_mean": ("consistency", "nees_mean"),
}
"""Metrics whose mean, median and IQR over seeds the summary's ``statistics`` gives."""

GROUP_RMSE_KEYS: dict[str, str] = {
    g: k for k, (g, m) in STATISTIC_METRICS.items() if m == "rmse" and g in GROUPS
}
"""Summary key of each group's RMSE, e.g. ``attitude_rmse_deg``."""


def per_seed_table(rows: pd.DataFrame) -> pd.DataFrame:
    """Rows of one pair as a table: index seed, columns ``(group, metric)``."""
    return rows.pivot_table(index="seed", columns=["group", "metric"], values="value", aggfunc="first", dropna=False)


def _seed_columns(rows: pd.DataFrame, seeds: list[int]) -> dict[tuple[str, str], np.ndarray]:
    """The values of :func:`per_seed_table` reindexed to ``seeds``, as ``{(group, metric): (runs,)}``
    (the first finite-or-not value of each seed, NaN for a seed without one: the pivot's "first"
    skips NaN, and so does this), without pandas' pivot (a fifth of a leaderboard build)."""
    position = {seed: i for i, seed in enumerate(seeds)}
    columns: dict[tuple[str, str], np.ndarray] = {}
    values = rows["value"].to_numpy(dtype=np.float64)
    for group, metric, seed, value in zip(rows["group"].tolist(), rows["metric"].tolist(), rows["seed"].tolist(), values):
        column = columns.get((group, metric))
        if column is None:
            column = columns[(group, metric)] = np.full(len(seeds), np.nan)
        i = position.get(seed)
        if i is not None and np.isnan(column[i]):
            column[i] = value
    return columns


def _column(table: dict[tuple[str, str], np.ndarray], group: str, metric: str, runs: int) -> np.ndarray:
    column = table.get((group, metric))
    return column.copy() if column is not None else np.full(runs, np.nan)


def _finite_max(values: np.ndarray) -> float:
    finite = values[np.isfinite(values)]
    return float(finite.max()) if finite.size else float("nan")


def summarize_pair(results: Results, estimator: str, scenario: str) -> dict[str, Any]:
    """The summary of one ``(estimator, scenario)`` (module docstring); JSON-compatible except
    that missing values are NaN (``fkn_bench.io.to_jsonable`` turns them into null)."""
    cells = results.cells(estimator, scenario)
    if not cells:
        raise KeyError(f"no results for {estimator} on {scenario}")
    rows = pd.concat([c.rows for c in cells], ignore_index=True)
    seeds = results.seeds(estimator, scenario)
    table = _seed_columns(rows, seeds)
    runs = len(seeds)

    def mean(group: str, metric: str) -> float:
        return summarize(_column(table, group, metric, runs)).mean

    nees, nis = results.pooled(estimator, scenario)
    anees = average_statistic(nees, NEES_DOF) if nees is not None else None
    anis = average_statistic(nis, NIS_DOF) if nis is not None else None
    lower, upper = chi2_interval(NEES_DOF, runs)
    nis_runs = int(np.max(nis.count)) if nis is not None and nis.count.size else 0
    nis_lower, nis_upper = chi2_interval(NIS_DOF, nis_runs) if nis_runs else (np.nan, np.nan)
    diverged = _column(table, "stability", "diverged", runs)
    lost = np.zeros(runs)  # lost track: any flag but the NEES test's (a failed run or an unknown flag counts)
    for flag in (*LOST_TRACK_REASONS, "failed"):
        lost = np.maximum(lost, np.nan_to_num(_column(table, "stability", flag, runs), nan=0.0))
    lost = np.where(np.isnan(diverged), 1.0, lost)
    primary = _column(table, *PRIMARY_SCORE, runs)
    failed = _column(table, "stability", "failed", runs)
    source = cells[0].source
    interval = mean_interval(primary)
    return {
        "estimator": estimator,
        "scenario": scenario,
        "seeds": seeds,
        "split": source.get("split"),
        "config_hash": source.get("config_hash"),
        "runs": runs,
        "failed_runs": int(np.nansum(failed)),
        "non_finite_runs": int(np.count_nonzero(~np.isfinite(primary))),
        "state_rmse": summarize(primary).mean,
        "state_rmse_ci": [interval.low, interval.high] if interval else None,
        "state_rmse_by_seed": [float(v) if np.isfinite(v) else float("nan") for v in primary],
        "rmse": {name: mean("state", f"rmse_{name}") for name in STATE_NAMES},
        **{GROUP_RMSE_KEYS[g]: mean(g, "rmse") for g in GROUPS},
        "settling_time_s": mean("settling", "time"),
        "settled_fraction": mean("settling", "settled"),
        "settling_time_by_group_s": {g: mean(g, "settling_time") for g in GROUPS},
        "diverged_fraction": float(np.mean(np.nan_to_num(diverged, nan=1.0))) if runs else float("nan"),
        "divergence_reasons": {r: mean("stability", r) for r in DIVERGENCE_REASONS},
        "lost_track_fraction": float(np.mean(lost)) if runs else float("nan"),
        "anees": anees.average if anees else float("nan"),
        "anees_bounds": [float(lower), float(upper)],
        "nees_in_bounds_fraction": anees.in_bounds_fraction if anees else float("nan"),
        "anis": anis.average if anis else float("nan"),
        "anis_bounds": [float(nis_lower), float(nis_upper)],
        "nis_in_bounds_fraction": anis.in_bounds_fraction if anis else float("nan"),
        "us_per_step": mean("cost", "us_per_step_online"),
        "us_per_step_batched": mean("cost", "us_per_step_batched"),
        "peak_memory_mib": _finite_max(_column(table, "cost", "peak_memory_mib", runs)),
        "statistics": {
            key: summarize(_column(table, group, metric, runs)).as_dict() for key, (group, metric) in STATISTIC_METRICS.items()
        },
        "errors": sorted({c.error for c in cells if c.error}),
        "trained_on": next((c.notes["trained_on"] for c in cells if c.notes.get("trained_on")), None),
        "non_causal": any(c.notes.get("non_causal") for c in cells),
    }


def summarize_results(results: Results, order: list[tuple[str, str]] | None = None) -> list[dict[str, Any]]:
    """Summaries of every pair, in ``order`` (default: sorted by estimator, then scenario)."""
    pairs = order if order is not None else results.pairs()
    return [summarize_pair(results, estimator, scenario) for estimator, scenario in pairs]
