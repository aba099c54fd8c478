"""The cross-scenario table (``leaderboards/cross-scenario.md``): the scores of
:func:`fkn_bench.harness.cross.cross_scores`, one row per estimator and training family, one column
per scored scenario."""

from __future__ import annotations

from collections.abc import Sequence

from fkn_bench.reporting.tables import Table

__all__ = ["cross_table"]


def cross_table(scores: dict[tuple[str, str, str], tuple[float, float]], scenarios: Sequence[str]) -> Table:
    """One row per (estimator, training family), one column per scored scenario."""
    rows = []
    for estimator, family in sorted({(e, f) for e, f, _ in scores}):
        cells = []
        for scenario in scenarios:
            value = scores.get((estimator, family, scenario))
            cells.append("–" if value is None else f"{value[0]:.4f}" + (f" ({value[1]:.0%} div.)" if value[1] else ""))
        rows.append([estimator, family, *cells])
    notes = [
        "13-state RMSE (mean over seeds, test split, from the loss cut) of each estimator with the committed "
        "parameters of each training family; (N% div.): share of seeds that diverged. Families: ds1, ds2 (the "
        "paper's constant rates), tumble (free tumbling: tumble-fast, tumble-flip, tumble-slow), default (the "
        "mixture used on recordings and user scenarios), ds1-noise-step (ds1 with a 5x measurement-noise step "
        "and torque bursts).",
    ]
    return Table("Trained on a family (rows), scored on a scenario (columns)", ["estimator", "trained on", *scenarios],
                 rows, notes, align=["l", "l"] + ["r"] * len(scenarios), name="cross-scenario")
