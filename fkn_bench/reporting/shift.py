"""The shift table (``leaderboards/shift.md`` and ``shift.csv``) of the scores that
:func:`fkn_bench.harness.shift.shift_scores` computes: each learned or tuned estimator's mean
13-state RMSE on its prior family (in distribution) and, per shift, the ratio of its mean on the
shifted prior to it. The targets (issue 39): no estimator worse than :data:`RATIO_TARGET` times its
in-distribution score, nor worse than :data:`~fkn_bench.harness.shift.REFERENCE` (manual-ekf) on
the same shift.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Mapping

from fkn_bench.harness.shift import REFERENCE, SHIFTS, ShiftScore
from fkn_bench.reporting.tables import Table, markdown_table

__all__ = ["RATIO_TARGET", "shift_misses", "shift_table", "shift_documents"]

RATIO_TARGET = 1.25
"""The largest shifted-to-in-distribution RMSE ratio the targets allow."""


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
