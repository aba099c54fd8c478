"""One estimator on one seed, kept whole (harness.trace): the series the figures draw."""

from __future__ import annotations

from fkn_bench.harness.sources import SimulatedSource
from fkn_bench.harness.trace import trace


def test_trace(short_ds1: SimulatedSource) -> None:
    run_trace = trace("manual-ekf", short_ds1, 3)
    assert run_trace.truth.shape == (200, 13) and run_trace.measurements.shape == (200, 7)
    assert run_trace.times[0] == 0.0 and run_trace.dt == 0.1
    assert run_trace.estimates.means.shape == (1, 200, 13)
