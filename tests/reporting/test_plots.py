"""Figures: drawn headless from a short run and written as PNG, readable at a glance
(:func:`fkn_bench.plotting.readability_problems`: no legend or text over data, no invisible line,
labels with units, no overlapping texts)."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np
import pytest
from matplotlib.lines import Line2D

from fkn_bench.harness import ResultStore, summarize_results
from fkn_bench.harness.ratios import RatioConvergence
from fkn_bench.harness.sources import SimulatedSource
from fkn_bench.harness.trace import Trace, trace
from fkn_bench.plotting import integer_axis, legend_beside, new_figure, readability_problems
from fkn_bench.reporting.plots import (comparison_figure, errors_figure, ratio_figure, save_figure, states_figure,
                                       uncertainty_figure)
from fkn_bench.reporting.reference import quoted_rows
from fkn_bench.reproduce.figures import omega_uncertainty_figure

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def run_trace(short_ds1: SimulatedSource) -> Trace:
    return trace("manual-ekf", short_ds1, 3)


@pytest.mark.parametrize("draw", [states_figure, uncertainty_figure, errors_figure])
def test_run_figures(run_trace: Trace, draw, tmp_path: Path) -> None:
    figure = draw(run_trace, steps=120)
    assert len(figure.axes) >= 4
    assert readability_problems(figure) == []
    path = save_figure(figure, tmp_path / "figure.png", dpi=40)
    assert path.read_bytes()[:8] == PNG_MAGIC
    assert [p.name for p in tmp_path.iterdir()] == ["figure.png"]  # no temporary left


def test_comparison_figure(small_results_dir: Path, tmp_path: Path) -> None:
    summaries = [s for s in summarize_results(ResultStore(small_results_dir).load()) if s["scenario"] == "ds1"]
    summaries[1] = {**summaries[1], "diverged_fraction": 0.85, "state_rmse": 1e30}  # a diverged mean
    figure = comparison_figure("ds1", summaries, quoted_rows("ds1"))
    labels = [t.get_text() for t in figure.axes[0].get_yticklabels()]
    assert labels == ["manual-ekf", "oracle-ekf  [85% diverged; RMSE 1e+30, off scale]", "paper: FlexKalmanNet (quoted)",
                      "paper: manual EKF (quoted)"]  # the diverged share in the label, not over the bars
    assert figure.axes[0].yaxis_inverted()  # the best at the top
    assert figure.axes[0].get_xlim()[1] < 0.1  # the other bars are not squashed by 1e30
    assert readability_problems(figure) == []
    assert save_figure(figure, tmp_path / "bars.png", dpi=40).read_bytes()[:8] == PNG_MAGIC


def test_omega_uncertainty_and_ratio_figures_are_readable(run_trace: Trace) -> None:
    assert readability_problems(omega_uncertainty_figure(run_trace, steps=120)) == []
    times = np.arange(0.0, 100.0, 0.5)
    errors = 0.1 * np.exp(-times / 30.0) * np.linspace(0.5, 2.0, 5)[:, None]
    result = RatioConvergence("ratios-ekf", "tumble-fast", tuple(range(5)), times, errors)
    figure = ratio_figure([result], at=60.0)
    assert len(figure.axes) == 1 and readability_problems(figure) == []


def test_the_readability_check_finds_each_kind_of_problem() -> None:
    """A figure that breaks every rule: the check names each problem (so the checks above can fail)."""
    figure = new_figure(4, 3)
    left, right = figure.subplots(1, 2)
    left.plot([1, 2, 3], [1, 3, 2], color="0.97", label="white line")
    left.legend(loc="center")  # over the data
    left.set_xlabel("epoch")  # no unit
    left.text(2, 2, "85% diverged")  # over the data
    right.plot([1, 2], [1, 2])
    right.set_ylabel("rate (rad/s)")  # the x axis has no label
    problems = "\n".join(readability_problems(figure))
    for expected in ("nearly invisible", "legend lies over the data", "'epoch' has no unit",
                     "y axis has tick labels but no label", "x axis has tick labels but no label",
                     "text '85% diverged' lies over a data area"):
        assert expected in problems
    fine = new_figure(4, 3)
    ax = fine.subplots()
    ax.plot([1, 2, 3], [0.5, 0.2, 0.1], label="loss")
    ax.set(xlabel="epoch (-)", ylabel="loss (-)")
    integer_axis(ax.xaxis)
    legend_beside(ax, [Line2D([], [], label="loss")])
    assert readability_problems(fine) == []
    fine.canvas.draw()
    assert all(float(t).is_integer() for t in ax.get_xticks())


def test_no_interactive_backend_is_touched(run_trace: Trace) -> None:
    backend = matplotlib.get_backend()
    states_figure(run_trace, steps=20)
    assert matplotlib.get_backend() == backend
