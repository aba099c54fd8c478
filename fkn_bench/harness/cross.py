"""Trained on X, scored on Y: each learned or tuned estimator with each family's committed
parameters on every named scenario (the scores of the cross-scenario table, which
:func:`fkn_bench.reporting.cross.cross_table` lays out).

A learned filter is fitted to a family's data (constant rate ``ds1``, ``ds2``; free tumbling
``tumble``; the ``default`` mixture; ``ds1-noise-step``, non-stationary noise); the leaderboards
run each scenario with its own family's parameters. This table shows what happens elsewhere: the
13-state RMSE (mean over seeds, test split, scored from the loss cut as on the leaderboards) and,
in brackets, the share of seeds that diverged. The diagonal-like cells (a family's parameters on
its own scenarios) repeat the leaderboards' numbers.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fkn_bench.envs import generate_episodes
from fkn_bench.harness.estimators import resolve_estimator
from fkn_bench.harness.shift import episode_scores
from fkn_bench.metrics import MetricSettings
from fkn_bench.scenarios import get_scenario
from fkn_bench.training.artifacts import committed_artifact_path

__all__ = ["cross_scores"]


def cross_scores(
    estimators: Sequence[str], families: Sequence[str], scenarios: Sequence[str], seeds: int,
    settings: MetricSettings | None = None,
) -> dict[tuple[str, str, str], tuple[float, float]]:
    """``{(estimator, family, scenario): (mean 13-state RMSE, diverged share)}`` for every
    committed artefact (pairs without one are left out)."""
    out: dict[tuple[str, str, str], tuple[float, float]] = {}
    for name in scenarios:
        scenario = get_scenario(name)
        episodes = generate_episodes(scenario, list(range(seeds)), split="test")
        for estimator_name in estimators:
            for family in families:
                path = committed_artifact_path(estimator_name, family)
                if path is None:
                    continue
                resolved = resolve_estimator(estimator_name, scenario, {"parameters": str(path)})
                if resolved.estimator is None:
                    continue
                scores = episode_scores(resolved.estimator, scenario, episodes, settings)
                rmse = np.asarray(scores.rmse)
                diverged = np.asarray(scores.lost) | np.asarray(scores.inconsistent)  # every divergence flag
                out[estimator_name, family, name] = (float(np.mean(np.where(np.isfinite(rmse), rmse, np.nan))),
                                                     float(np.mean(diverged)))
    return out
