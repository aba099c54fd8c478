"""One estimator on one seed, kept whole: the time series the figures draw."""

from __future__ import annotations

from dataclasses import dataclass

from fkn_bench.estimators import Estimates
from fkn_bench.harness.estimators import ResolvedEstimator, resolve_estimator
from fkn_bench.harness.sources import EpisodeSource
from fkn_bench.runtime import torch_threads
from fkn_bench.types import ArrayB, ArrayF

__all__ = ["Trace", "trace"]


@dataclass(frozen=True, eq=False)
class Trace:
    """Truth, measurements and estimates of one run (batch axis removed).

    Attributes:
        estimator, scenario, seed: what ran.
        dt: sample interval, s.
        times: ``(T,)`` s from the start of the run (the split's first sample is 0).
        truth: ``(T, 13)``; measurements: ``(T, 7)`` (NaN where missing); valid: ``(T,)``.
        estimates: the estimator's :class:`~fkn_bench.estimators.Estimates` with batch size 1.
    """

    estimator: str
    scenario: str
    seed: int
    dt: float
    times: ArrayF
    truth: ArrayF
    measurements: ArrayF
    valid: ArrayB
    estimates: Estimates


def trace(estimator: ResolvedEstimator | str, source: EpisodeSource, seed: int) -> Trace:
    """Run ``estimator`` (resolved for ``source``'s scenario, or a name resolved here) on ``seed`` of
    ``source`` (one torch thread) and keep every series."""
    resolved = resolve_estimator(estimator, source.scenario) if isinstance(estimator, str) else estimator
    if resolved.estimator is None:
        raise ValueError(f"estimator {resolved.name!r} is not available: {resolved.error}")
    episodes = source.load([seed])
    dt = float(episodes.scenario.dt)
    with torch_threads():
        estimates = resolved.estimator.estimate(episodes.measurements.copy(), episodes.valid.copy(), dt)
    return Trace(
        estimator=resolved.name,
        scenario=source.label,
        seed=int(seed),
        dt=dt,
        times=episodes.times - episodes.times[0],
        truth=episodes.truth[0],
        measurements=episodes.measurements[0],
        valid=episodes.valid[0],
        estimates=estimates,
    )
