"""Figures: drawn headless from a short run and written as PNG."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import pytest

from fkn_bench.harness import ResultStore, summarize_results
from fkn_bench.harness.plots import comparison_figure, errors_figure, save_figure, states_figure, uncertainty_figure
from fkn_bench.harness.reference import quoted_rows
from fkn_bench.harness.sources import SimulatedSource
from fkn_bench.harness.trace import Trace, trace

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def run_trace(short_ds1: SimulatedSource) -> Trace:
    return trace("manual-ekf", short_ds1, 3)


def test_trace(run_trace: Trace) -> None:
    assert run_trace.truth.shape == (200, 13) and run_trace.measurements.shape == (200, 7)
    assert run_trace.times[0] == 0.0 and run_trace.dt == 0.1
    assert run_trace.estimates.means.shape == (1, 200, 13)


@pytest.mark.parametrize("draw", [states_figure, uncertainty_figure, errors_figure])
def test_run_figures(run_trace: Trace, draw, tmp_path: Path) -> None:
    figure = draw(run_trace, steps=120)
    assert len(figure.axes) >= 4
    path = save_figure(figure, tmp_path / "figure.png", dpi=40)
    assert path.read_bytes()[:8] == PNG_MAGIC
    assert [p.name for p in tmp_path.iterdir()] == ["figure.png"]  # no temporary left


def test_comparison_figure(small_results_dir: Path, tmp_path: Path) -> None:
    summaries = [s for s in summarize_results(ResultStore(small_results_dir).load()) if s["scenario"] == "ds1"]
    figure = comparison_figure("ds1", summaries, quoted_rows("ds1"))
    labels = [t.get_text() for t in figure.axes[0].get_xticklabels()]
    assert labels == ["manual-ekf", "oracle-ekf", "paper: FlexKalmanNet (quoted)", "paper: manual EKF (quoted)"]
    assert save_figure(figure, tmp_path / "bars.png", dpi=40).read_bytes()[:8] == PNG_MAGIC


def test_no_interactive_backend_is_touched(run_trace: Trace) -> None:
    backend = matplotlib.get_backend()
    states_figure(run_trace, steps=20)
    assert matplotlib.get_backend() == backend
