"""Evaluating filters the paper's way: long test sequences, scored after the loss cut.

The paper's protocol (section 4.3): the filter runs over whole sequences of the data set rather
than training batches, with a measurement every 10 steps (the scenario's schedule), and the RMSE
against the noise-free truth measures accuracy. Here every evaluation runs one estimator on the
test split of ``seeds`` episodes of a scenario (seed 0 is the held-out tenth of the training
recording, the others are further recordings of the same scenario) and scores each with
:func:`fkn_bench.metrics.score_run` (the harness's scoring: from step ``cut`` = 100, the loss cut,
quaternions sign-aligned). Values are means over the seeds of the per-run values, the harness's
convention.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from fkn_bench.estimators import Estimator
from fkn_bench.harness.estimators import ResolvedEstimator
from fkn_bench.harness.sources import SimulatedSource
from fkn_bench.harness.trace import Trace, trace
from fkn_bench.metrics import GROUPS, MetricSettings, score_run, summarize
from fkn_bench.runtime import torch_threads
from fkn_bench.scenarios import Scenario
from fkn_bench.types import STATE_NAMES

__all__ = ["Evaluation", "evaluate", "run_trace", "UNSTABLE_REASONS"]

UNSTABLE_REASONS = ("non_finite", "cholesky_failed", "error_growth")


@dataclass(frozen=True)
class Evaluation:
    """One estimator on one scenario over several seeds (means over seeds).

    Attributes:
        estimator: label of the estimator (e.g. ``learned-ds1``, ``manual``).
        scenario: scenario name.
        seeds: the evaluated test-split seeds.
        state_rmse: the 13-state RMSE.
        component_rmse: RMSE per state component (``qw`` ... ``vz``).
        group_rmse: RMSE of the group error magnitudes (attitude deg, position m, rate rad/s,
            velocity m/s).
        settling_time_s: latest group settling time (harness definition; a run that never
            settles counts with its length).
        settled_fraction: share of runs whose four groups all settled.
        diverged_fraction: share of runs flagged as diverged by any of the harness's tests.
        divergence_reasons: share of runs flagged by each test (``non_finite``,
            ``cholesky_failed``, ``error_growth``, ``nees_high``).
        unstable_fraction: share of runs that blew up (:data:`UNSTABLE_REASONS`: non-finite
            estimates, a failed Cholesky factorisation or a final error above the initial one);
            the NEES test alone flags overconfidence, not instability.
        per_seed_state_rmse: the 13-state RMSE of each seed.
    """

    estimator: str
    scenario: str
    seeds: tuple[int, ...]
    state_rmse: float
    component_rmse: dict[str, float]
    group_rmse: dict[str, float]
    settling_time_s: float
    settled_fraction: float
    diverged_fraction: float
    divergence_reasons: dict[str, float] = field(default_factory=dict)
    unstable_fraction: float = 0.0
    per_seed_state_rmse: tuple[float, ...] = field(default_factory=tuple)

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "seeds": list(self.seeds), "per_seed_state_rmse": list(self.per_seed_state_rmse)}


def evaluate(
    estimator: Estimator,
    label: str,
    scenario: Scenario,
    seeds: Sequence[int],
    *,
    settings: MetricSettings | None = None,
) -> Evaluation:
    """Run ``estimator`` on the test split of ``seeds`` of ``scenario`` and score it (module
    docstring)."""
    settings = settings or MetricSettings()
    episodes = SimulatedSource(scenario, "test").load(list(seeds))
    dt = float(scenario.dt)
    with torch_threads():
        estimates = estimator.estimate(np.array(episodes.measurements), np.array(episodes.valid), dt)
    scores = score_run(episodes.truth, estimates.means, dt, error_covariances=estimates.error_covariances,
                       settings=settings)
    return Evaluation(
        estimator=label,
        scenario=scenario.name,
        seeds=tuple(int(s) for s in seeds),
        state_rmse=summarize(scores.state_rmse).mean,
        component_rmse={name: summarize(scores.component_rmse[:, i]).mean for i, name in enumerate(STATE_NAMES)},
        group_rmse={g: summarize(scores.group_statistics[g]["rmse"]).mean for g in GROUPS},
        settling_time_s=summarize(scores.settling_time).mean,
        settled_fraction=float(np.mean(scores.settled)),
        diverged_fraction=float(np.mean(scores.divergence.diverged)),
        divergence_reasons={k: float(np.mean(v)) for k, v in scores.divergence.as_dict().items() if k != "diverged"},
        unstable_fraction=float(np.mean(np.any([getattr(scores.divergence, r) for r in UNSTABLE_REASONS], axis=0))),
        per_seed_state_rmse=tuple(float(v) for v in scores.state_rmse),
    )


def run_trace(estimator: Estimator, label: str, scenario: Scenario, seed: int) -> Trace:
    """One run kept whole for the figures (:func:`fkn_bench.harness.trace.trace`, filed under ``label``)."""
    return trace(ResolvedEstimator(label, scenario.name, estimator), SimulatedSource(scenario, "test"), seed)
