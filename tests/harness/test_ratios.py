"""Inertia-ratio convergence of the ratio-estimating rigid-body EKF (harness.ratios, plot --ratios;
its figure: tests/reporting/test_plots.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from fkn_bench.cli import main
from fkn_bench.harness.estimators import resolve_estimator
from fkn_bench.harness.ratios import ratio_convergence
from fkn_bench.scenarios import get_scenario


def test_ratio_error_falls_on_a_free_tumble() -> None:
    scenario = get_scenario("tumble-flip")
    result = ratio_convergence(resolve_estimator("rigid-body-ekf-ratios", scenario), scenario, 2, 200.0)
    assert result.errors.shape == (2, 2001) and result.times[-1] == pytest.approx(200.0)
    start, end = result.errors[:, 0].min(), result.errors[:, -1].max()  # the first sample is measured
    assert start > 0.1 > 0.02 > end  # from the isotropic prior (0.129 off) to the body's ratios
    assert result.share_below(0.02, 200.0) == 1.0 and result.share_below(0.02, 0.0) == 0.0


def test_estimators_without_ratios_are_refused() -> None:
    scenario = get_scenario("tumble-flip")
    with pytest.raises(ValueError, match="estimates no inertia ratios"):
        ratio_convergence(resolve_estimator("manual-ekf", scenario), scenario, 1, 20.0)


def test_plot_ratios_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["plot", "--ratios", "--scenario", "tumble-flip", "--seeds", "1", "--duration", "60",
                 "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "of 1 seeds have inertia-ratio error < 0.02 at 600 s" in out
    assert (tmp_path / "ratios-rigid-body-ekf-ratios-tumble-flip.png").stat().st_size > 10_000
    assert main(["plot", "--ratios", "--estimator", "manual-ekf", "--scenario", "tumble-flip", "--seeds", "1",
                 "--duration", "10", "--out", str(tmp_path)]) == 2
