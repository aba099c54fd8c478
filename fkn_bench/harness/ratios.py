"""How fast an estimator that estimates inertia ratios finds them: error over time, and a figure.

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
from fkn_bench.filters.rigid_body import inertia_ratios
from fkn_bench.harness.estimators import ResolvedEstimator
from fkn_bench.plotting import legend_below, new_figure
from fkn_bench.scenarios import Scenario
from fkn_bench.types import ArrayF

__all__ = ["RatioConvergence", "ratio_convergence", "ratio_figure"]


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


def ratio_figure(results: list[RatioConvergence], *, threshold: float = 0.02, at: float = 600.0):  # noqa: ANN201
    """Inertia-ratio error ``max |k_est - k_true|`` (-, log scale) over time (s) per scenario: the
    median and the 10-90% band over seeds, the threshold and the time at which it is checked
    marked; the legend below the axes."""
    figure = new_figure(9.0, 4.4)
    ax = figure.add_subplot(1, 1, 1)
    for result in results:
        median = np.nanmedian(result.errors, axis=0)
        low, high = np.nanpercentile(result.errors, [10, 90], axis=0)
        share = result.share_below(threshold, at)
        line = ax.semilogy(result.times, median, label=f"{result.scenario} (median; {share:.0%} of "
                                                       f"{len(result.seeds)} seeds < {threshold} at {at:g} s)")[0]
        ax.fill_between(result.times, low, high, color=line.get_color(), alpha=0.2, linewidth=0)
    ax.axhline(threshold, color="k", linestyle="--", linewidth=0.8, label=f"threshold {threshold:g}")
    ax.axvline(at, color="k", linestyle=":", linewidth=0.8, label=f"checked at {at:g} s")
    ax.set(xlabel="time since the first sample (s)", ylabel="max |k_est - k_true| (-)",
           title=f"{results[0].estimator}: inertia-ratio error (band: 10-90% of seeds)")
    legend_below(figure, ax.get_legend_handles_labels()[0], ncols=1 if len(results) > 1 else 3)
    return figure
