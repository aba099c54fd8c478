"""RMSE per component, 13-state RMSE and error-magnitude statistics on known answers."""

from __future__ import annotations

import numpy as np
import pytest

from fkn_bench.metrics import MAGNITUDE_STATISTICS, component_rmse, magnitude_statistics, state_rmse


def test_constant_error_rmse_is_the_constant() -> None:
    errors = np.broadcast_to(np.arange(13, dtype=float) * 0.01, (3, 50, 13))
    assert np.allclose(component_rmse(errors), np.arange(13) * 0.01)
    expected = np.sqrt(np.mean((np.arange(13) * 0.01) ** 2))
    assert np.allclose(state_rmse(errors), expected)


def test_alternating_sign_error() -> None:
    errors = np.zeros((1, 4, 13))
    errors[0, :, 5] = [1.0, -1.0, 1.0, -1.0]
    assert component_rmse(errors)[0, 5] == pytest.approx(1.0)
    assert state_rmse(errors)[0] == pytest.approx(np.sqrt(1 / 13))


def test_magnitude_statistics() -> None:
    values = np.arange(1.0, 101.0)[None]  # 1 .. 100
    stats = magnitude_statistics(values)
    assert tuple(stats) == MAGNITUDE_STATISTICS
    assert stats["rmse"][0] == pytest.approx(np.sqrt(np.mean(np.arange(1.0, 101.0) ** 2)))
    assert stats["median"][0] == pytest.approx(50.5)
    assert stats["p95"][0] == pytest.approx(95.05)
    assert stats["max"][0] == 100.0


def test_statistics_keep_runs_apart_and_propagate_nan() -> None:
    values = np.array([[1.0, 1.0], [2.0, np.nan]])
    stats = magnitude_statistics(values)
    assert stats["rmse"][0] == 1.0
    assert all(np.isnan(stats[name][1]) for name in MAGNITUDE_STATISTICS)


def test_empty_window_is_rejected() -> None:
    with pytest.raises(ValueError):
        component_rmse(np.zeros((1, 0, 13)))
    with pytest.raises(ValueError):
        magnitude_statistics(np.zeros((1, 0)))
