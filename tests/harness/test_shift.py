"""The shift table: a family's estimators scored on shifted priors, as ratios to their own score."""

from __future__ import annotations

import math

import pytest

from fkn_bench.harness.shift import (
    REFERENCE,
    SHIFTS,
    ShiftScore,
    shift_misses,
    shift_scores,
    shift_table,
    shifted_scenario,
)
from fkn_bench.scenarios import PRIOR_FAMILIES, get_scenario


def test_every_prior_family_has_its_shifts_and_each_changes_only_its_fields() -> None:
    assert set(SHIFTS) == set(PRIOR_FAMILIES)
    for family, shifts in SHIFTS.items():
        base = get_scenario(family)
        labels = [s.label for s in shifts]
        assert {"faster spin", "drift x5", "2x rate", "1/2 rate", "noise x3"} <= set(labels)
        assert ("inertia +-25%" in labels) == (base.dynamics == "free")
        for shift in shifts:
            shifted = shifted_scenario(family, shift)
            assert shifted.model_family == base.model_family  # the family's parameters run there
            assert shifted.replace(**{k: getattr(base, k) for k in shift.fields}, name=base.name,
                                   description=base.description, tags=base.tags) == base
    faster = shifted_scenario("spin", SHIFTS["spin"][0])
    assert faster.omega0_magnitude[0] >= get_scenario("spin").omega0_magnitude[1]  # beyond the training range


def test_scores_of_the_reference_on_two_episodes() -> None:
    scores = shift_scores(["spin"], 2, estimators=(), steps=300)
    columns = {c for _, c, _ in scores}
    assert columns == {"in-distribution", *[s.label for s in SHIFTS["spin"]]}
    assert {n for *_, n in scores} == {REFERENCE}
    own, noisy = scores["spin", "in-distribution", REFERENCE], scores["spin", "noise x3", REFERENCE]
    assert len(own.rmse) == 2 and own.lost_count == 0 and noisy.mean > 2 * own.mean
    table = shift_table(scores, "spin")
    assert table.header[:3] == ["estimator", "in-distribution", "NEES flag"] and table.rows[0][0] == REFERENCE
    assert table.rows[0][table.header.index("noise x3")].startswith(f"{noisy.mean / own.mean:.2f}x")


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


@pytest.mark.parametrize("family", sorted(SHIFTS))
def test_shifted_scenarios_are_valid_and_named_apart(family: str) -> None:
    names = {shifted_scenario(family, s).name for s in SHIFTS[family]}
    assert len(names) == len(SHIFTS[family]) and not names & set(PRIOR_FAMILIES[family])


def test_each_estimator_runs_its_familys_parameters_on_every_shift(monkeypatch: pytest.MonkeyPatch) -> None:
    """A shifted prior is no named scenario, where a trained estimator would otherwise run the
    default mixture's parameters: the table must score the family's own."""
    from fkn_bench.harness import shift

    asked: list[tuple[str, str, dict]] = []

    def resolve(name, scenario, options=None):  # noqa: ANN001, ANN202
        asked.append((name, scenario.name, dict(options or {})))
        return type("Unavailable", (), {"estimator": None})()

    monkeypatch.setattr(shift, "resolve_estimator", resolve)
    shift_scores(["spin"], 1, estimators=("flexkalmannet", "no-such-estimator"), steps=50)
    trained = [options for name, _, options in asked if name == "flexkalmannet"]
    assert len(trained) == 1 + len(SHIFTS["spin"])
    assert all(o["parameters"].endswith("flexkalmannet-spin.json") for o in trained)
    assert {name for name, *_ in asked} == {REFERENCE, "flexkalmannet"}  # no parameters: left out
