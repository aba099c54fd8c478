"""Accuracy metrics of one run per sequence: RMSE per state component, the 13-state RMSE, and
the RMSE, median, 95th percentile and maximum of the group error magnitudes.

All functions take the errors of the *scored window* (the caller slices off the transient, see
:mod:`fkn_bench.metrics.scoring`) with the time axis second to last or last, and reduce over time
only, so each sequence of a batch keeps its own value (``(B, ...)``).
"""

from __future__ import annotations

import numpy as np

from fkn_bench.types import ArrayF, Float

__all__ = ["component_rmse", "state_rmse", "magnitude_statistics", "MAGNITUDE_STATISTICS"]

MAGNITUDE_STATISTICS: tuple[str, ...] = ("rmse", "median", "p95", "max")
"""Statistics of an error magnitude over time that :func:`magnitude_statistics` returns."""


def _errors(errors: ArrayF) -> ArrayF:
    errors = np.asarray(errors, dtype=np.float64)
    if errors.ndim != 3 or errors.shape[1] == 0:
        raise ValueError(f"errors must have shape (B, T, n) with T >= 1 (got {errors.shape})")
    return errors


def component_rmse(errors: Float[ArrayF, "B T n"]) -> Float[ArrayF, "B n"]:
    """Root mean square over time of each component: ``(B, T, n) -> (B, n)``.

    With :func:`fkn_bench.metrics.errors.component_errors` this is the paper's per-variable RMSE
    table (FlexKalmanNet, "RMSE of each variable of the state vector").
    """
    return np.sqrt(np.mean(np.square(_errors(errors)), axis=1))


def state_rmse(errors: Float[ArrayF, "B T 13"]) -> Float[ArrayF, "B"]:
    """The 13-state RMSE per sequence, ``(B, T, 13) -> (B,)``: the root of the mean over time and
    over all components of the squared component errors (the paper's test loss, an MSE against
    all 13 true states; components keep their units, so position errors in m dominate).

    This is fkn-bench's primary score (lower is better).
    """
    return np.sqrt(np.mean(np.square(_errors(errors)), axis=(1, 2)))


def magnitude_statistics(magnitudes: Float[ArrayF, "B T"]) -> dict[str, Float[ArrayF, "B"]]:
    """RMSE, median, 95th percentile (linear interpolation) and maximum over time of
    non-negative error magnitudes: ``(B, T) -> {name: (B,)}`` (names in
    :data:`MAGNITUDE_STATISTICS`). A NaN anywhere in a sequence makes all its values NaN."""
    magnitudes = np.asarray(magnitudes, dtype=np.float64)
    if magnitudes.ndim != 2 or magnitudes.shape[1] == 0:
        raise ValueError(f"magnitudes must have shape (B, T) with T >= 1 (got {magnitudes.shape})")
    return {
        "rmse": np.sqrt(np.mean(np.square(magnitudes), axis=1)),
        "median": np.median(magnitudes, axis=1),
        "p95": np.percentile(magnitudes, 95.0, axis=1),
        "max": np.max(magnitudes, axis=1),
    }
