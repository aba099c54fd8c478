"""Scored on priors it never saw: each learned or tuned estimator, trained on a prior family, run on
shifted versions of that family's prior (the scores of the shift table, ``leaderboards/shift.md``,
which :mod:`fkn_bench.reporting.shift` writes).

A prior family (``spin``, ``free-tumble``; :data:`fkn_bench.scenarios.PRIOR_FAMILIES`) trains its
estimators on episodes drawn from its stated prior. Each shift here changes one thing about that
prior or its measurements (:data:`SHIFTS`): rates beyond the training range, faster drift, a wider
inertia spread, double and half the measurement rate, three times the noise. A shifted scenario
keeps its family's ``model_family``, so every estimator runs with the parameters it learned on the
family; it is scored on the same test episodes (seeds ``0 .. N-1``: the same standard-normal draws,
so the comparison is paired) as on the family's own scenario, with ``manual-ekf`` (a fixed,
untrained tuning, :data:`REFERENCE`) beside it.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fkn_bench.envs import generate_episodes
from fkn_bench.harness.estimators import resolve_estimator
from fkn_bench.metrics import MetricSettings, score_run
from fkn_bench.scenarios import Scenario, get_scenario
from fkn_bench.training.artifacts import committed_artifact_path

__all__ = ["Shift", "SHIFTS", "SHIFT_ESTIMATORS", "REFERENCE", "ShiftScore", "shifted_scenario", "shift_scores",
           "episode_scores"]

REFERENCE = "manual-ekf"
"""The untrained reference every shifted score is compared with."""

SHIFT_ESTIMATORS: tuple[str, ...] = (
    "flexkalmannet", "flexkalmannet-rigid-body", "flexkalmannet-tv", "direct-tuned-ekf", "nll-tuned-ekf",
    "kalmannet", "recursive-kalmannet", "split-kalmannet", "cholesky-kalmannet", "akhlaghi", "sage-husa", "vbakf",
)
"""The learned and tuned estimators: each runs with its family's committed parameters."""


@dataclass(frozen=True)
class Shift:
    """One change to a family's prior: a column ``label``, what it changes (``description``) and
    the scenario fields that change it."""

    label: str
    description: str
    fields: Mapping[str, Any] = field(default_factory=dict)


_COMMON = (
    Shift("drift x5", "drift N(0, (5 cm/s)^2) per axis (trained: 1 cm/s)", {"velocity0_std": 0.05}),
    Shift("2x rate", "a measurement every 5 steps, 2 Hz (trained: 1 Hz)", {"measurement_every": 5}),
    Shift("1/2 rate", "a measurement every 20 steps, 0.5 Hz (trained: 1 Hz)", {"measurement_every": 20}),
    Shift("noise x3", "three times the measurement noise, 0.3 m and 0.3 rad (trained: 0.1)", {"noise_scale": 3.0}),
)

SHIFTS: dict[str, tuple[Shift, ...]] = {
    "spin": (
        Shift("faster spin", "rate magnitude log-uniform in [0.6, 1.5] rad/s (trained: [0.03, 0.6])",
              {"omega0_magnitude": (0.6, 1.5)}),
        *_COMMON,
    ),
    "free-tumble": (
        Shift("faster spin", "body rate magnitude log-uniform in [0.6, 1.2] rad/s (trained: [0.05, 0.6])",
              {"omega0_magnitude": (0.6, 1.2)}),
        Shift("inertia +-25%", "principal moments x U(0.75, 1.25) per axis (trained: x U(0.9, 1.1))",
              {"inertia_error": 0.25}),
        *_COMMON,
    ),
}
"""The shifted priors of each prior family, in table order."""


def shifted_scenario(family: str, shift: Shift) -> Scenario:
    """The family's headline scenario with ``shift`` applied (same ``model_family``)."""
    base = get_scenario(family)
    slug = shift.label.replace(" ", "-").replace("/", "-").replace("+-", "pm").replace("%", "pc")
    return base.replace(name=f"{family}~{slug}", description=f"{family} with {shift.description}", tags=("shift",),
                        **dict(shift.fields))


@dataclass(frozen=True)
class ShiftScore:
    """Per-episode 13-state RMSEs of one estimator on one scenario, which episodes lost track
    (error growth, a non-finite estimate or covariance, a covariance not positive definite:
    :mod:`fkn_bench.metrics.stability`) and, apart, which failed the NEES consistency test (the
    filter sure of a wrong estimate over the final window: ``nees_high``)."""

    rmse: tuple[float, ...]
    lost: tuple[bool, ...]
    inconsistent: tuple[bool, ...] = ()

    @property
    def mean(self) -> float:
        """Mean 13-state RMSE over the episodes (``inf`` when one is not finite: it lost track)."""
        values = np.array(self.rmse)
        return float(values.mean()) if np.isfinite(values).all() else math.inf

    @property
    def lost_count(self) -> int:
        return int(sum(self.lost))

    @property
    def inconsistent_count(self) -> int:
        return int(sum(self.inconsistent))


def episode_scores(estimator: Any, scenario: Scenario, episodes: Any, settings: MetricSettings | None = None) -> ShiftScore:
    """A copy of ``estimator`` run on ``episodes`` of ``scenario`` and scored per episode (the
    leaderboards' metric settings by default): the shift and cross-scenario tables' one scoring."""
    estimates = copy.deepcopy(estimator).estimate(episodes.measurements, episodes.valid, scenario.dt)
    scores = score_run(episodes.truth, estimates.means, scenario.dt, error_covariances=estimates.error_covariances,
                       settings=settings)
    rmse = np.asarray(scores.state_rmse, dtype=float)
    flags = scores.divergence
    lost = np.asarray(flags.lost_track, dtype=bool) | ~np.isfinite(rmse)
    return ShiftScore(tuple(float(v) for v in rmse), tuple(bool(v) for v in lost),
                      tuple(bool(v) for v in np.asarray(flags.nees_high, dtype=bool)))


def shift_scores(
    families: Sequence[str], seeds: int, estimators: Sequence[str] = SHIFT_ESTIMATORS,
    settings: MetricSettings | None = None, progress: Callable[[str], None] | None = None, steps: int | None = None,
) -> dict[tuple[str, str, str], ShiftScore]:
    """``{(family, column, estimator): ShiftScore}`` over test episodes ``0 .. seeds-1``; column
    ``"in-distribution"`` is the family's own scenario, the others the labels of :data:`SHIFTS`.
    Every estimator but :data:`REFERENCE` runs with its committed parameters of the family
    (``parameters=<estimator>-<family>.json``); those without any are left out. ``steps``: episodes of that many
    samples instead of the family's (a quick look; the table uses the family's)."""
    out: dict[tuple[str, str, str], ShiftScore] = {}
    names = [REFERENCE, *[e for e in estimators if e != REFERENCE]]
    for family in families:
        columns = [("in-distribution", get_scenario(family))]
        columns += [(shift.label, shifted_scenario(family, shift)) for shift in SHIFTS[family]]
        for column, scenario in columns:
            scenario = scenario if steps is None else scenario.replace(n_steps=int(steps))
            episodes = generate_episodes(scenario, seeds, split="test")
            for name in names:
                options = {}
                if name != REFERENCE:  # the family's own parameters (a shifted scenario is no named one,
                    path = committed_artifact_path(name, family)  # which would get the default mixture's)
                    if path is None:
                        continue
                    options = {"parameters": str(path)}
                resolved = resolve_estimator(name, scenario, options)
                if resolved.estimator is None:
                    continue
                if progress is not None:
                    progress(f"{family} / {column} / {name}")
                out[family, column, name] = episode_scores(resolved.estimator, scenario, episodes, settings)
    return out
