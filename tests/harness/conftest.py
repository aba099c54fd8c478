"""Shared fixtures of the harness tests: short scenarios, test estimators, a small stored grid."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fkn_bench.estimators import Estimate, Estimates, Estimator, estimator_names, make_estimator, registry
from fkn_bench.harness import ResultStore, SimulatedSource, build_grid, run_grid
from fkn_bench.scenarios import get_scenario


@pytest.fixture(scope="session")
def short_ds1() -> SimulatedSource:
    """ds1 with 2000 samples: a 200-step test split (100 scored steps after the default cut)."""
    return SimulatedSource(get_scenario("ds1", n_steps=2000))


@pytest.fixture(scope="session")
def short_ds2() -> SimulatedSource:
    return SimulatedSource(get_scenario("ds2", n_steps=2000))


class RaisingEstimator(Estimator):
    """Raises in estimate(): a broken estimator the grid must survive."""

    name = "raising"

    def estimate(self, measurements: Any, mask: Any, dt: float) -> Estimates:
        raise RuntimeError("boom: the filter blew up")

    def reset(self, *, dt: float) -> None:
        pass

    def step(self, observation: Any) -> Estimate:
        raise RuntimeError("boom")

    def to_config(self) -> dict[str, Any]:
        return {}


class NaNEstimator(RaisingEstimator):
    """Returns NaN estimates from step 150 on, and has no online mode."""

    name = "nan"

    def estimate(self, measurements: Any, mask: Any, dt: float) -> Estimates:
        inner = make_estimator("manual-ekf").estimate(measurements, mask, dt)
        means = np.array(inner.means)
        means[:, 150:] = np.nan
        return Estimates(means=means, error_covariances=inner.error_covariances)


@pytest.fixture
def test_estimators(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """Register ``raising`` and ``nan`` in an isolated copy of the registry."""
    estimator_names()  # load the built-ins first
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    registry.register_estimator("raising", lambda scenario=None, **_: RaisingEstimator())
    registry.register_estimator("nan", lambda scenario=None, **_: NaNEstimator())
    yield


@pytest.fixture(scope="session")
def small_results_dir(tmp_path_factory: pytest.TempPathFactory, short_ds1: SimulatedSource,
                      short_ds2: SimulatedSource) -> Path:
    """A stored grid: manual-ekf and oracle-ekf on short ds1 and ds2, seeds 0..11 (8 cells)."""
    root = tmp_path_factory.mktemp("results")
    cells = build_grid(["manual-ekf", "oracle-ekf"], [short_ds1, short_ds2], range(12))
    run_grid(cells, store=ResultStore(root), progress=False)
    return root
