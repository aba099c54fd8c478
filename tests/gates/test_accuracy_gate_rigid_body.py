"""The accuracy gate's second half: the Kalman filters on the rigid-body model (``conftest.py`` says
how the gate is split and why the rigid-body UKF and MEKF are gated on the free tumbles only)."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from fkn_bench.gates import accuracy

pytestmark = pytest.mark.slow(seconds=30)  # the gate's second half: its session fixture (conftest.py)


def test_committed_results_reproduce(rigid_body_report: accuracy.AccuracyReport, gated_estimator: str,
                                     gate_check: Callable) -> None:
    gate_check(rigid_body_report, gated_estimator)


def test_every_free_tumble_is_covered(rigid_body_report: accuracy.AccuracyReport, free_tumbles: tuple[str, ...]) -> None:
    tumbles = set(free_tumbles)
    gated = {e for e, _, _ in rigid_body_report.compared}
    assert gated >= {"rigid-body-ekf", "rigid-body-ekf-ratios", "rigid-body-ukf", "rigid-body-mekf"}
    assert tumbles <= {s for _, s, _ in rigid_body_report.compared}  # each free tumble by some estimator
    for name in gated:  # and each estimator on some free tumble
        assert tumbles & {s for e, s, _ in rigid_body_report.compared if e == name}, name
