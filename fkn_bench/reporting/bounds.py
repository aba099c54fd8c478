"""How far from the best possible: the bound row and the efficiency of each estimator.

A scenario's stored posterior Cramér-Rao bound (:mod:`fkn_bench.metrics.bound`, stored by
:mod:`fkn_bench.harness.bounds`) holds per-seed bounds of the 13-state score and of each group's
RMSE. An estimator's *efficiency* is ``bound / RMSE`` for each of them, the bound averaged over the
seeds the estimator was scored on (:func:`bound_means`): 1.0 is the best possible, 0.5 an error
twice the bound's.

It can exceed 1 by a few percent without any estimator beating the bound: the leaderboard's RMSE
is the mean over episodes of each episode's RMSE, and the mean of square roots is below the root
of the mean square that the bound bounds (the model-matched oracle, whose own covariance is the
bound, scores 1.02 on ``free-tumble``'s position: ``leaderboards/free-tumble.md``), and the bound of a nonlinear model is evaluated along
each episode's truth. Well above 1 it says the estimator knows more than the scenario's stated
prior (the paper's fixed-truth scenarios: every episode the same rate, which the learned filters
memorise) or that the bound's inlier model does not describe the data (outliers).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from fkn_bench.harness.summary import GROUP_RMSE_KEYS
from fkn_bench.metrics import GROUPS
from fkn_bench.metrics.bound import efficiency

__all__ = ["BOUND_LABEL", "BOUND_NOTE", "EFFICIENCY_KEYS", "bound_means", "efficiencies", "shown_standard_error",
           "format_efficiency"]

BOUND_LABEL = "bound (PCRB)"
"""The label of a scenario's bound row."""

EFFICIENCY_KEYS: tuple[str, ...] = ("state", *GROUPS)
"""The scores an efficiency is given for: the 13-state RMSE and each group's RMSE."""

BOUND_NOTE = (
    "bound (PCRB): the posterior Cramér-Rao bound (Tichavský, Muravchik & Nehorai, IEEE TSP 1998), the "
    "smallest error any estimator can reach given the scenario's stated prior, its dynamics and measurement noise "
    "and each episode's measurement schedule, on the scale of each RMSE column (mean over the test episodes ± its "
    "Monte-Carlo standard error; fkn_bench.metrics.bound). Outliers and sign flips are not in it: it is the "
    "bound of the inlier model. efficiency: bound / RMSE (1.0 is the best possible; a few percent above 1 is the "
    "mean of per-episode RMSEs, below the root mean square the bound bounds; far above 1, an estimator that "
    "knows more than the stated prior, e.g. a fixed truth it was trained on; – where the bound is 0: the stated "
    "prior fixes that quantity, as the paper's scenarios fix the rate, position and velocity)."
)


def bound_means(bound: Mapping[str, Any], seeds: Sequence[int] | None = None) -> dict[str, float]:
    """``{"state": ..., group: ...}``: the stored ``bound``'s per-seed values (``Bound.to_dict()``)
    averaged over ``seeds`` (default: all of them; seeds it does not hold are left out)."""
    index = {int(s): i for i, s in enumerate(bound["seeds"])}
    rows = [index[int(s)] for s in seeds if int(s) in index] if seeds is not None else list(index.values())
    if not rows:
        return {k: math.nan for k in EFFICIENCY_KEYS}
    out = {"state": float(np.mean(np.asarray(bound["state_rmse"])[rows]))}
    out.update({g: float(np.mean(np.asarray(bound["group_rmse"][g])[rows])) for g in GROUPS})
    return out


def efficiencies(summary: Mapping[str, Any], bound: Mapping[str, Any] | None) -> dict[str, float]:
    """``{"state": ..., group: ...}`` efficiencies of an estimator's summary
    (:func:`fkn_bench.harness.summary.summarize_pair`) against the scenario's stored ``bound``
    (NaN without one)."""
    if bound is None:
        return {k: math.nan for k in EFFICIENCY_KEYS}
    means = bound_means(bound, summary.get("seeds"))
    rmse = {"state": summary["state_rmse"], **{g: summary[GROUP_RMSE_KEYS[g]] for g in GROUPS}}
    return {k: efficiency(means[k], _float(rmse[k])) for k in EFFICIENCY_KEYS}


def shown_standard_error(mean: float, error: float | None) -> float | None:
    """The Monte-Carlo standard error a report shows: 0 where it is rounding noise (at most 1e-9
    of the mean: every episode has the same bound, e.g. the position's under one measurement
    schedule)."""
    return 0.0 if error is not None and abs(error) <= 1e-9 * abs(mean) else error


def format_efficiency(value: float | None, missing: str = "–") -> str:
    """An efficiency to two decimals, ``missing`` where it is undefined."""
    return missing if value is None or not math.isfinite(value) else f"{value:.2f}"


def _float(value: Any) -> float:
    return math.nan if value is None else float(value)
