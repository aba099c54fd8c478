"""How fast an estimator that estimates inertia ratios finds them: error over time (drawn by
:func:`fkn_bench.reporting.plots.ratio_figure`).

The estimator (e.g. ``rigid-body-ekf-ratios``) reports the log ratios ``k = [ln(Jx/Jy),
ln(Jy/Jz)]`` in ``Estimates.extras["inertia_ratios"]``; the truth is each seed's body
(:func:`fkn_bench.envs.episodes.true_inertia`, which includes a scenario's inertia error). The
error at a time is ``max |k_est - k_true|`` over the two ratios: 0.02 is a 2% error of a ratio of
moments. Runs start at the episode's first sample (``split="full"``), where the estimator knows
nothing of the body.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from fkn_bench.envs import generate_episodes
from fkn_bench.envs.episodes import true_inertia
from fkn_bench.harness.estimators import ResolvedEstimator
from fkn_bench.models.rigid_body import inertia_ratios
from fkn_bench.scenarios import Scenario
from fkn_bench.types import ArrayF

__all__ = ["RatioConvergence", "ratio_convergence"]


@dataclass(frozen=True)
class RatioConvergence:
    """Inertia-ratio errors of one estimator on one scenario.

    Attributes:
        estimator, scenario: names.
        seeds: episode seeds.
        times: ``(T,)`` s from the episode start.
        errors: ``(S, T)`` ``max |k_est - k_true|`` per seed and time (NaN before initialisation).
    """

    estimator: str
    scenario: str
    seeds: tuple[int, ...]
    times: ArrayF
    errors: ArrayF

    def _at(self, time: float) -> ArrayF:
        """``(S,)`` errors at ``time`` (s; the last sample when later)."""
        return self.errors[:, min(int(np.searchsorted(self.times, time)), len(self.times) - 1)]

    def share_below(self, threshold: float, time: float) -> float:
        """Share of seeds whose error at ``time`` (s) is below ``threshold``."""
        return float(np.mean(self._at(time) < threshold))

    def median_at(self, time: float) -> float:
        """Median over seeds of the error at ``time`` (s)."""
        return float(np.median(self._at(time)))


def ratio_convergence(resolved: ResolvedEstimator, scenario: Scenario, seeds: int, duration: float) -> RatioConvergence:
    """Run ``resolved`` on the first ``duration`` seconds of seeds ``0 .. seeds-1``."""
    if resolved.estimator is None:
        raise ValueError(f"{resolved.name} is not available for {scenario.name}: {resolved.error}")
    estimator = copy.deepcopy(resolved.estimator)
    steps = min(scenario.n_steps, int(round(duration / scenario.dt)) + 1)
    episodes = generate_episodes(scenario, list(range(seeds)), split="full").window(0, steps)
    estimates = estimator.estimate(episodes.measurements, episodes.valid, scenario.dt)
    if "inertia_ratios" not in estimates.extras:
        raise ValueError(f"{resolved.name} estimates no inertia ratios (try rigid-body-ekf-ratios)")
    truth = np.array([inertia_ratios(J) for J in true_inertia(scenario, episodes.seeds)])
    errors = np.abs(estimates.extras["inertia_ratios"] - truth[:, None, :]).max(-1)
    if estimates.initialised is not None:
        errors = np.where(estimates.initialised, errors, np.nan)
    return RatioConvergence(resolved.name, scenario.name, episodes.seeds, episodes.times, errors)
