"""The shift scores: a family's estimators scored on shifted priors (the table: tests/reporting/test_shift.py)."""

from __future__ import annotations

import pytest

from fkn_bench.harness.shift import REFERENCE, SHIFTS, shift_scores, shifted_scenario
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
