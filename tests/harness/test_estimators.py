"""Resolving estimators: one build per pair, fingerprints, the default choice and its notes."""

from __future__ import annotations

import pytest

from fkn_bench.estimators import UnknownEstimatorError, estimator_names, make_estimator, registry
from fkn_bench.harness import SelectionError, SimulatedSource, build_grid, resolve, resolve_estimator, select_estimators
from fkn_bench.scenarios import get_scenario


@pytest.fixture
def counted(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Register ``counted`` (a manual EKF; available on ds1 only) in an isolated registry; the list
    records one entry per factory call."""
    estimator_names()
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    calls: list[str] = []

    def factory(scenario=None, **_):
        calls.append(scenario.name)
        if scenario.name != "ds1":
            raise FileNotFoundError("no parameters")
        return make_estimator("manual-ekf")

    registry.register_estimator("counted", factory)
    return calls


def test_each_pair_is_built_once(counted: list[str]) -> None:
    scenarios = [get_scenario("ds1", n_steps=2000)]
    (resolved,) = resolve(["counted"], scenarios)
    cells = build_grid([resolved], [SimulatedSource(scenarios[0])], range(25))
    assert counted == ["ds1"] and len(cells) == 3 and all(c.resolved is resolved for c in cells)
    assert resolved.available and len(resolved.fingerprint) == 16
    assert resolved.fingerprint == resolve_estimator("manual-ekf", scenarios[0]).fingerprint


def test_unavailable_pairs(counted: list[str]) -> None:
    ds1, ds2 = get_scenario("ds1"), get_scenario("ds2")
    missing = resolve_estimator("counted", ds2)
    assert not missing.available and missing.estimator is None and missing.fingerprint == ""
    assert missing.error == "FileNotFoundError: no parameters"
    with pytest.raises(SelectionError, match="'counted' is not available for scenario ds2"):
        select_estimators(["counted"], [ds1, ds2])
    selection = select_estimators(None, [ds1, ds2], every=True)
    assert ("counted", "ds1") in [(r.name, r.scenario) for r in selection.resolved]
    assert "skipping counted on ds2 (not available: FileNotFoundError: no parameters)" in selection.notes
    with pytest.raises(UnknownEstimatorError, match="valid estimators"):
        resolve(["no-such-estimator"], [ds1])


def test_default_prefers_flexkalmannet(monkeypatch: pytest.MonkeyPatch) -> None:
    estimator_names()
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))

    def unavailable(scenario=None, **_):
        raise FileNotFoundError("no trained parameters")

    registry.register_estimator("flexkalmannet", unavailable, overwrite=True)
    selection = select_estimators(None, [get_scenario("ds1")])
    assert selection.names == ["manual-ekf"]
    assert selection.notes == ["flexkalmannet is not available (FileNotFoundError: no trained parameters); "
                               "running manual-ekf"]
    registry.register_estimator("flexkalmannet", lambda scenario=None, **_: make_estimator("manual-ekf"), overwrite=True)
    assert select_estimators(None, [get_scenario("ds1")]).names == ["flexkalmannet"]


def test_a_network_retrained_into_the_same_file_gets_another_fingerprint(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A network estimator's configuration names its weights by path: the fingerprint covers their
    content, so that cells of the network that was there before are recomputed, not reused."""
    import shutil
    from pathlib import Path

    from fkn_bench.training.artifacts import committed_artifact_path, weights_of_artifact

    weights = weights_of_artifact(committed_artifact_path("kalmannet", "ds1"), "kalmannet")
    mine = tmp_path / "checkpoint.pt"
    shutil.copy(weights, mine)
    scenario = get_scenario("ds1")
    first = resolve_estimator("kalmannet", scenario, {"checkpoint": str(mine)})
    assert first.available and first.fingerprint == resolve_estimator("kalmannet", scenario, {"checkpoint": str(mine)}).fingerprint
    shutil.copy(Path(str(weights).replace("-ds1.", "-ds2.")), mine)  # retrained: other weights, same file
    assert resolve_estimator("kalmannet", scenario, {"checkpoint": str(mine)}).fingerprint != first.fingerprint
    assert resolve_estimator("manual-ekf", scenario).fingerprint  # estimators naming no file: as before
