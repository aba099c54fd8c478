"""The shift table: a family's estimators scored on shifted priors, as ratios to their own score."""

from __future__ import annotations

import math

from fkn_bench.harness.shift import REFERENCE, ShiftScore
from fkn_bench.reporting.shift import shift_misses, shift_table


def _score(mean: float, lost: int = 0) -> ShiftScore:
    return ShiftScore((mean, mean), tuple(i < lost for i in range(2)), (False, False))


def test_missed_targets_are_named_with_their_numbers() -> None:
    scores = {
        ("spin", "in-distribution", REFERENCE): _score(0.02),
        ("spin", "drift x5", REFERENCE): _score(0.04),
        ("spin", "in-distribution", "learned"): _score(0.01, lost=1),
        ("spin", "drift x5", "learned"): _score(0.05),
        ("spin", "noise x3", "learned"): _score(0.012),
        ("spin", "noise x3", REFERENCE): _score(0.06),
        ("spin", "1/2 rate", "learned"): _score(math.inf),
    }
    misses = shift_misses(scores)
    assert "learned on spin: lost track on 1 of 2 episodes" in misses
    assert "learned on spin / drift x5: 5.00x its in-distribution score (0.05 vs 0.01)" in misses
    assert "learned on spin / drift x5: 0.05, worse than manual-ekf's 0.04" in misses
    assert any(m.startswith("learned on spin / 1/2 rate: infx") for m in misses)  # lost: never a pass
    assert not any("noise x3" in m for m in misses)  # 1.2x and better than the reference
    row = [r for r in shift_table(scores, "spin").rows if r[0] == "learned"][0]
    assert row[1] == "0.0100, 1 lost" and row[4] == "5.00x (0.0500) !" and row[3] == "–"


def test_the_reference_leads_and_each_shift_is_a_ratio_to_the_own_score() -> None:
    scores = {("spin", "in-distribution", REFERENCE): _score(0.02), ("spin", "noise x3", REFERENCE): _score(0.05)}
    table = shift_table(scores, "spin")
    assert table.header[:3] == ["estimator", "in-distribution", "NEES flag"] and table.rows[0][0] == REFERENCE
    assert table.rows[0][table.header.index("noise x3")] == "2.50x (0.0500)"  # the reference misses no target
