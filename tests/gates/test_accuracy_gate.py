"""The accuracy gate (:mod:`fkn_bench.gates.accuracy`), run by the default test command.

``test_committed_results_reproduce[<estimator>]`` recomputes seeds 0 and 1 of every registered
estimator on every named scenario (the rigid-body ones in ``test_accuracy_gate_rigid_body.py``;
``conftest.py`` says how the gate is split) and compares every deterministic metric with the committed
``leaderboards/results`` (tolerances in the module's docstring). A registered estimator without
committed results fails here with the command that adds them, unless it is listed in
``EXCLUDED`` in ``conftest.py``. The other tests show the gate at work on small grids: a worse estimator fails
with a readable table, an intended change passes once accepted.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from fkn_bench.estimators import Estimates, estimator_names, registry
from fkn_bench.estimators.kalman import KalmanEstimator
from fkn_bench.gates import accuracy
from fkn_bench.gates.accuracy import ACCEPT_COMMAND, ADD_COMMAND, Tolerance, run_accuracy_gate, tolerance_for

pytestmark = pytest.mark.slow(seconds=65)  # the gate's first half: its session fixture (conftest.py)

REPO = Path(__file__).resolve().parents[2]

def test_committed_results_reproduce(constant_rate_report: accuracy.AccuracyReport, gated_estimator: str,
                                     gate_check: Callable) -> None:
    gate_check(constant_rate_report, gated_estimator)


def test_no_orphaned_committed_results(constant_rate_report: accuracy.AccuracyReport) -> None:
    orphaned = [p for p in constant_rate_report.problems if p.kind == "orphaned"]
    assert not orphaned, constant_rate_report.message(orphaned[0].estimator)


def test_every_named_scenario_is_covered(constant_rate_report: accuracy.AccuracyReport) -> None:
    """Every named scenario is gated, but the prior families' stress variants, whose truths are
    their gated headline's and whose streams are ds1's gated variants' (conftest.PRIOR_STRESS)."""
    from fkn_bench.scenarios import PRIOR_FAMILIES, get_scenario, scenario_names

    stress = {name for names in PRIOR_FAMILIES.values() for name in names[1:]}
    gated = {s for _, s, _ in constant_rate_report.compared}
    assert gated == set(scenario_names()) - stress and set(PRIOR_FAMILIES) <= gated
    assert all(get_scenario(name).model_family in gated for name in stress)
    assert all(len(seeds) == accuracy.GATE_SEEDS for _, _, seeds in constant_rate_report.compared)


# ---------------------------------------------------------------------------------- the gate at work
@pytest.fixture
def isolated_registry(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    estimator_names()  # load the built-ins first
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    yield


@pytest.fixture
def small_committed(tmp_path: Path) -> Path:
    """Committed results of manual-ekf on ds1, seeds 0-1, written by ``fkn-bench run --out``."""
    from fkn_bench.cli import main

    out = tmp_path / "results"
    assert main(["run", "--estimator", "manual-ekf", "--scenario", "ds1", "--seeds", "2", "--out", str(out),
                 "--no-progress", "--json"]) == 0
    return out


def _worse_position(monkeypatch: pytest.MonkeyPatch, offset: float) -> None:
    """Inject a regression: every position estimate of the Kalman estimators off by ``offset`` m."""
    original = KalmanEstimator.estimate

    def estimate(self: KalmanEstimator, measurements, mask, dt) -> Estimates:  # noqa: ANN001
        result = original(self, measurements, mask, dt)
        means = np.array(result.means)
        means[..., 4:7] += offset
        return dataclasses.replace(result, means=means)

    monkeypatch.setattr(KalmanEstimator, "estimate", estimate)


def test_unchanged_code_passes(small_committed: Path) -> None:
    report = run_accuracy_gate(small_committed, estimators=["manual-ekf"], scenarios=["ds1"])
    assert report.passed(), report.message()
    assert report.compared == [("manual-ekf", "ds1", (0, 1))]
    assert report.compared_values > 100


def test_worse_rmse_fails_with_a_readable_diff_table(small_committed: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _worse_position(monkeypatch, 0.05)
    report = run_accuracy_gate(small_committed, estimators=["manual-ekf"], scenarios=["ds1"], seeds=1)
    assert not report.passed("manual-ekf")
    message = report.message("manual-ekf")
    print(message)
    header = message.splitlines()[1]
    for column in ("estimator", "scenario", "seed", "metric", "committed", "now", "change", "verdict", "tolerance"):
        assert column in header
    rmse = next(d for d in report.differences if d.name == "state/rmse")
    assert (rmse.estimator, rmse.scenario, rmse.seed) == ("manual-ekf", "ds1", 0)
    assert rmse.now > rmse.committed and rmse.verdict == "worse" and rmse.change.startswith("+")
    assert "manual-ekf  ds1" in message and "state/rmse" in message
    assert ACCEPT_COMMAND in message
    assert all(d.seed == 0 for d in report.differences)  # seeds=1: only seed 0 recomputed


def test_a_change_within_tolerance_passes(small_committed: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _worse_position(monkeypatch, 1e-12)  # rounding-sized: what another machine's libraries may do
    report = run_accuracy_gate(small_committed, estimators=["manual-ekf"], scenarios=["ds1"], seeds=1)
    assert report.passed(), report.message()


def test_accepting_a_change_makes_the_gate_pass(small_committed: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The accept command (its ``--rerun`` recomputes cells whose configuration is unchanged)."""
    from fkn_bench.cli import main

    _worse_position(monkeypatch, 0.05)
    assert not run_accuracy_gate(small_committed, estimators=["manual-ekf"], scenarios=["ds1"], seeds=1).passed()
    assert "--rerun" in ACCEPT_COMMAND
    # resuming without --rerun keeps the old cells: the change is not accepted
    args = ["run", "--estimator", "manual-ekf", "--scenario", "ds1", "--seeds", "2", "--out", str(small_committed),
            "--no-progress", "--json"]
    assert main(args) == 0
    assert not run_accuracy_gate(small_committed, estimators=["manual-ekf"], scenarios=["ds1"], seeds=1).passed()
    assert main([*args, "--rerun"]) == 0
    report = run_accuracy_gate(small_committed, estimators=["manual-ekf"], scenarios=["ds1"], seeds=1)
    assert report.passed(), report.message()


def test_estimator_without_committed_results_fails_with_instructions(
    small_committed: Path, isolated_registry: None
) -> None:
    registry.register_estimator("my-filter", lambda scenario=None, **_: KalmanEstimator(name="my-filter"))
    report = run_accuracy_gate(small_committed, estimators=["manual-ekf", "my-filter"], scenarios=["ds1"], seeds=1)
    assert report.passed("manual-ekf") and not report.passed("my-filter")
    (problem,) = report.problems_of("my-filter")
    assert problem.kind == "missing"
    message = report.message("my-filter")
    assert "my-filter on ds1" in message and ADD_COMMAND in message
    excluded = run_accuracy_gate(small_committed, estimators=["manual-ekf", "my-filter"], scenarios=["ds1"], seeds=1,
                                 exclude={"my-filter": "experimental"})
    assert excluded.passed() and excluded.excluded == {"my-filter": "experimental"}


def test_unavailable_estimator_is_skipped(small_committed: Path, isolated_registry: None) -> None:
    def untrained(scenario=None, **_):  # noqa: ANN001, ANN202
        raise FileNotFoundError("no trained parameters")

    registry.register_estimator("untrained", untrained)
    report = run_accuracy_gate(small_committed, estimators=["untrained"], scenarios=["ds1"])
    assert report.passed() and report.skipped == [("untrained", "ds1", "FileNotFoundError: no trained parameters")]


def test_reconfigured_estimator_is_stale(small_committed: Path, isolated_registry: None) -> None:
    registry.register_estimator(
        "manual-ekf", lambda scenario=None, **_: KalmanEstimator(name="manual-ekf", r_std=[0.2] * 7), overwrite=True
    )
    report = run_accuracy_gate(small_committed, estimators=["manual-ekf"], scenarios=["ds1"], seeds=1)
    assert [p.kind for p in report.problems] == ["stale"]
    assert "configuration changed" in report.message() and report.differences


def test_orphaned_results_fail(small_committed: Path, isolated_registry: None) -> None:
    del registry._REGISTRY["manual-ekf"]
    report = run_accuracy_gate(small_committed, scenarios=["ds1"], seeds=1)  # every registered estimator
    (orphaned,) = [p for p in report.problems if p.kind == "orphaned"]
    assert orphaned.estimator == "manual-ekf" and "cells/manual-ekf" in orphaned.detail
    assert {p.kind for p in report.problems} == {"orphaned", "missing"}  # the others: not in this small store


@pytest.mark.parametrize(
    ("group", "metric", "committed", "now", "ok"),
    [
        ("state", "rmse", 0.0192, 0.0192 * (1 + 5e-7), True),
        ("state", "rmse", 0.0192, 0.0192 * (1 + 2e-6), False),
        ("state", "rmse", 0.0, 5e-13, True),
        ("state", "rmse", float("nan"), float("nan"), True),
        ("state", "rmse", 0.0192, float("nan"), False),
        ("stability", "diverged", 0.0, 1.0, False),
        ("attitude", "settled", 1.0, 1.0, True),
        ("consistency", "nis_count", 140.0, 141.0, False),
        ("consistency", "nees_mean", 3.87, 3.87 * (1 - 1e-7), True),
    ],
)
def test_tolerances(group: str, metric: str, committed: float, now: float, ok: bool) -> None:
    assert tolerance_for(group, metric).allows(committed, now) is ok


def test_tolerance_text() -> None:
    assert str(tolerance_for("stability", "failed")) == "exact"
    assert str(Tolerance(1e-6, 1e-12)) == "1e-12 + 1e-06 rel"


def test_configurations_do_not_depend_on_the_checkout_location() -> None:
    """The committed results carry each estimator's configuration fingerprint; a fingerprint that
    included an absolute path would make every other checkout (CI's clean clone) look stale."""
    import json

    from fkn_bench.estimators import make_estimator
    from fkn_bench.scenarios import get_scenario
    from fkn_bench.training.artifacts import artifact_path

    package_root = str(artifact_path("akhlaghi", "ds1").parents[2])  # the checkout (or site-packages/fkn_bench)
    for name in estimator_names():
        for scenario in ("ds1", "ds2"):
            try:
                config = make_estimator(name, scenario=get_scenario(scenario)).to_config()
            except Exception:  # noqa: BLE001 - unavailable for this scenario
                continue
            text = json.dumps(config, default=str)
            assert package_root not in text and str(REPO) not in text, f"{name} on {scenario}: {text[:300]}"


def test_a_run_diverged_then_and_now_is_compared_by_its_flags_only() -> None:
    import pandas as pd

    def rows(diverged: float, rmse: float) -> pd.DataFrame:
        base = {"estimator": "x", "scenario": "s", "seed": 0, "unit": ""}
        return pd.DataFrame([{**base, "group": "stability", "metric": "diverged", "value": diverged},
                             {**base, "group": "state", "metric": "rmse", "value": rmse}])

    same, _ = accuracy._compare(rows(1.0, 3e37), rows(1.0, 5e36), accuracy.TOLERANCES)
    assert same == []  # both blew up: the chaotic values are not compared
    (change,) = accuracy._compare(rows(0.0, 0.02), rows(0.0, 0.03), accuracy.TOLERANCES)[0]
    assert change.name == "state/rmse"
    flipped, _ = accuracy._compare(rows(1.0, 3e37), rows(0.0, 0.02), accuracy.TOLERANCES)
    assert {d.name for d in flipped} == {"stability/diverged", "state/rmse"}
