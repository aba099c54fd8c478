"""Scored on priors it never saw: each learned or tuned estimator, trained on a prior family, on
shifted versions of that family's prior (the shift table, ``leaderboards/shift.md``).

A prior family (``spin``, ``free-tumble``; :data:`fkn_bench.scenarios.PRIOR_FAMILIES`) trains its
estimators on episodes drawn from its stated prior. Each shift here changes one thing about that
prior or its measurements (:data:`SHIFTS`): rates beyond the training range, faster drift, a wider
inertia spread, double and half the measurement rate, three times the noise. A shifted scenario
keeps its family's ``model_family``, so every estimator runs with the parameters it learned on the
family; it is scored on the same test episodes (seeds ``0 .. N-1``: the same standard-normal draws,
so the comparison is paired) as on the family's own scenario, and reported as the ratio of its mean
13-state RMSE there to its mean on the family (its in-distribution score), with ``manual-ekf`` (a
fixed, untrained tuning) beside it. The targets (issue 39): no estimator worse than
:data:`RATIO_TARGET` times its in-distribution score, nor worse than manual-ekf on the same shift.
"""

from __future__ import annotations

import copy
import csv
import io
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fkn_bench.envs import generate_episodes
from fkn_bench.harness.estimators import resolve_estimator
from fkn_bench.harness.tables import Table, markdown_table
from fkn_bench.metrics import MetricSettings, score_run
from fkn_bench.scenarios import Scenario, get_scenario
from fkn_bench.training.artifacts import artifact_path

__all__ = ["Shift", "SHIFTS", "SHIFT_ESTIMATORS", "REFERENCE", "RATIO_TARGET", "ShiftScore", "shifted_scenario",
           "shift_scores", "shift_table", "shift_misses", "shift_documents", "episode_scores"]

RATIO_TARGET = 1.25
"""The largest shifted-to-in-distribution RMSE ratio the targets allow."""

REFERENCE = "manual-ekf"
"""The untrained reference every shifted score is compared with."""

SHIFT_ESTIMATORS: tuple[str, ...] = (
    "flexkalmannet", "flexkalmannet-rigid-body", "flexkalmannet-tv", "direct-tuned-ekf", "nll-tuned-ekf",
    "kalmannet", "recursive-kalmannet", "akhlaghi", "sage-husa", "vbakf",
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
                    path = artifact_path(name, family)  # which would get the default mixture's)
                    if not path.is_file():
                        continue
                    options = {"parameters": str(path)}
                resolved = resolve_estimator(name, scenario, options)
                if resolved.estimator is None:
                    continue
                if progress is not None:
                    progress(f"{family} / {column} / {name}")
                out[family, column, name] = episode_scores(resolved.estimator, scenario, episodes, settings)
    return out


def _number(value: float, digits: int = 4) -> str:
    """``value`` with ``digits`` decimals, or in 3 significant digits when it is large (a filter
    that blew up) or not finite."""
    return f"{value:.{digits}f}" if abs(value) < 1e3 else f"{value:.3g}"


def shift_misses(scores: Mapping[tuple[str, str, str], ShiftScore]) -> list[str]:
    """The targets missed, one sentence each with the numbers: a lost track in distribution, a
    shifted score above :data:`RATIO_TARGET` times the in-distribution one or above manual-ekf's."""
    misses = []
    for (family, column, name), score in sorted(scores.items()):
        if name == REFERENCE:
            continue
        own = scores.get((family, "in-distribution", name))
        if column == "in-distribution":
            if score.lost_count:
                misses.append(f"{name} on {family}: lost track on {score.lost_count} of {len(score.lost)} episodes")
            continue
        reference = scores.get((family, column, REFERENCE))
        ratio = score.mean / own.mean if own is not None and own.mean > 0 else math.nan
        if not ratio <= RATIO_TARGET:
            misses.append(f"{name} on {family} / {column}: {_number(ratio, 2)}x its in-distribution score "
                          f"({score.mean:.4g} vs {own.mean if own else math.nan:.4g})")
        if reference is not None and not score.mean <= reference.mean:
            misses.append(f"{name} on {family} / {column}: {score.mean:.4g}, worse than {REFERENCE}'s "
                          f"{reference.mean:.4g}")
    return misses


def shift_table(scores: Mapping[tuple[str, str, str], ShiftScore], family: str) -> Table:
    """One row per estimator: its in-distribution mean 13-state RMSE, then per shift the ratio of
    its shifted mean to it (and the shifted mean); ``!`` marks a missed target."""
    columns = ["in-distribution", "NEES flag", *[s.label for s in SHIFTS[family]]]
    names = [REFERENCE, *sorted({n for f, _, n in scores if f == family and n != REFERENCE})]
    rows = []
    for name in names:
        own = scores.get((family, "in-distribution", name))
        if own is None:
            continue
        lost = f", {own.lost_count} lost" if own.lost_count else ""
        cells = [f"{_number(own.mean)}{lost}", f"{own.inconsistent_count}/{len(own.rmse)}"]
        for column in columns[2:]:
            score, reference = scores.get((family, column, name)), scores.get((family, column, REFERENCE))
            if score is None:
                cells.append("–")
                continue
            ratio = score.mean / own.mean if own.mean > 0 else math.nan
            missed = name != REFERENCE and (not ratio <= RATIO_TARGET
                                            or (reference is not None and not score.mean <= reference.mean))
            cells.append(f"{_number(ratio, 2)}x ({_number(score.mean)}){' !' if missed else ''}")
        rows.append([name, *cells])
    notes = [f"{s.label}: {s.description}" for s in SHIFTS[family]] + [
        f"In-distribution: the mean 13-state RMSE over the test episodes of {family} (from the loss cut), with the "
        "number of episodes that lost track (error growth, a non-finite estimate, a covariance not positive definite). "
        "NEES flag: the episodes in distribution whose NEES exceeded the 99.9% quantile of chi2(12) at every step of "
        "the final window (the filter sure of a wrong estimate; consistency, not a lost track). Each shift: the ratio of the mean "
        "on the shifted prior (same seeds) to the in-distribution mean, and in brackets the shifted mean. "
        f"`!`: a target missed (ratio above {RATIO_TARGET:g}, or worse than {REFERENCE} on the same shift).",
    ]
    return Table(f"{family}: trained on the family's prior, scored on shifted priors", ["estimator", *columns], rows,
                 notes, align=["l"] + ["r"] * len(columns), name=f"shift-{family}")


def shift_documents(scores: Mapping[tuple[str, str, str], ShiftScore], seeds: int) -> tuple[str, str]:
    """``shift.md`` (a table per family, then the missed targets) and ``shift.csv`` (one row per
    family, column and estimator: mean RMSE, lost tracks, NEES flags, episodes) of ``scores``."""
    families = [family for family in SHIFTS if any(f == family for f, _, _ in scores)]
    misses = shift_misses(scores)
    text = (f"# Shift table ({seeds} test episodes per cell)\n\n"
            f"Regenerate: `fkn-bench leaderboard --shift --seeds {seeds}`\n\n"
            "Each learned or tuned estimator runs with the parameters it learned on its prior family's training "
            "episodes, on that family's test episodes (in-distribution) and on the same episodes drawn from shifted "
            f"priors; {REFERENCE} (untrained) beside them. Targets: no lost track in distribution; on every shift "
            f"at most {RATIO_TARGET:g}x the in-distribution score and no worse than {REFERENCE}. A shift that takes "
            "information away (half the measurement rate, three times the noise) raises every filter's error, "
            f"{REFERENCE}'s too: there the ratio beside {REFERENCE}'s own is what tells a filter that generalises "
            "from one that does not.\n\n"
            + "\n\n".join(markdown_table(shift_table(scores, family)) for family in families)
            + "\n\n## Targets missed\n\n" + ("\n".join(f"- {m}" for m in misses) if misses else "None.") + "\n")
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["family", "estimator", "column", "mean_rmse", "lost", "nees_flagged", "episodes"])
    writer.writerows([f, n, c, repr(v.mean), v.lost_count, v.inconsistent_count, len(v.rmse)]
                     for (f, c, n), v in sorted(scores.items()))
    return text, buffer.getvalue()
