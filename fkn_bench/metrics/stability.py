"""Divergence of a run: the stability verdict reported apart from accuracy.

A run is flagged diverged (this benchmark's rule; the NEES test after Bar-Shalom, Li &
Kirubarajan 2001, sec. 5.4) when any of these holds:

* ``non_finite``: the estimate (or its error covariance, when reported) holds NaN or infinity in
  the scored window;
* ``cholesky_failed``: the error covariance is not positive definite (its Cholesky factorisation
  fails) at some step of the scored window;
* ``error_growth``: for some state group the RMS error over the final window exceeds both the RMS
  error over the initial window and an absolute floor (:data:`DEFAULT_GROWTH_FLOORS`). The floor
  keeps runs whose initial error happens to be tiny (e.g. a velocity that starts exactly right)
  from being flagged for ordinary steady-state noise;
* ``nees_high``: the NEES exceeds the ``nees_quantile`` (99.9%) quantile of chi2(12) at every
  step of the final window: the filter is sure of an estimate that is wrong (the classical sense
  of Kalman filter divergence, Bar-Shalom et al. 2001, sec. 5.4).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from fkn_bench.metrics.consistency import NEES_DOF, chi2_upper
from fkn_bench.types import ArrayB, ArrayF, Bool, Float

__all__ = ["DEFAULT_GROWTH_FLOORS", "DIVERGENCE_REASONS", "LOST_TRACK_REASONS", "DivergenceFlags", "error_growth", "nees_high", "window_rms"]

DEFAULT_GROWTH_FLOORS: Mapping[str, float] = {
    "attitude": 20.0,  # deg: twice ds1's raw measurement error level (9.9 deg)
    "position": 0.5,  # m: about three times ds1's raw measurement error (0.17 m)
    "omega": 0.05,  # rad/s: two thirds of ds1's true rate (0.075 rad/s)
    "velocity": 0.05,  # m/s
}
"""Final-window RMS errors below these never count as error growth (group units: deg, m,
rad/s, m/s)."""

DIVERGENCE_REASONS: tuple[str, ...] = ("non_finite", "cholesky_failed", "error_growth", "nees_high")
"""The flags of :class:`DivergenceFlags`, in the order of the module docstring."""
LOST_TRACK_REASONS: tuple[str, ...] = ("non_finite", "cholesky_failed", "error_growth")
"""The flags that mean the estimate lost the track (its error grew, or it or its covariance broke);
``nees_high``, a filter sure of an estimate that is wrong, is a consistency verdict reported apart."""


@dataclass(frozen=True, eq=False)
class DivergenceFlags:
    """Per-run divergence flags, each ``(B,)`` bool; ``diverged`` is their union."""

    non_finite: Bool[ArrayB, "B"]
    cholesky_failed: Bool[ArrayB, "B"]
    error_growth: Bool[ArrayB, "B"]
    nees_high: Bool[ArrayB, "B"]

    @property
    def lost_track(self) -> Bool[ArrayB, "B"]:
        """The union of :data:`LOST_TRACK_REASONS` (``nees_high`` left out)."""
        return self.non_finite | self.cholesky_failed | self.error_growth

    @property
    def diverged(self) -> Bool[ArrayB, "B"]:
        return self.non_finite | self.cholesky_failed | self.error_growth | self.nees_high

    def as_dict(self) -> dict[str, Bool[ArrayB, "B"]]:
        """The flags by name (:data:`DIVERGENCE_REASONS`) plus ``diverged``."""
        return {name: getattr(self, name) for name in DIVERGENCE_REASONS} | {"diverged": self.diverged}


def window_rms(magnitudes: Float[ArrayF, "B T"], start: int, stop: int) -> Float[ArrayF, "B"]:
    """RMS over steps ``[start, stop)`` of ``(B, T)`` magnitudes, ``(B,)`` (NaN propagates)."""
    magnitudes = np.asarray(magnitudes, dtype=np.float64)
    if not 0 <= start < stop <= magnitudes.shape[1]:
        raise ValueError(f"window [{start}, {stop}) is not inside {magnitudes.shape[1]} steps")
    return np.sqrt(np.mean(np.square(magnitudes[:, start:stop]), axis=1))


def error_growth(
    magnitudes: Mapping[str, Float[ArrayF, "B T"]],
    *,
    initial_steps: int,
    final_steps: int,
    floors: Mapping[str, float] = DEFAULT_GROWTH_FLOORS,
) -> Bool[ArrayB, "B"]:
    """``(B,)``: True where, for some group, the RMS over the last ``final_steps`` exceeds both the
    RMS over the first ``initial_steps`` and the group's floor. NaN errors count as growth."""
    grown: ArrayB | None = None
    for group, values in magnitudes.items():
        values = np.asarray(values, dtype=np.float64)
        T = values.shape[1]
        initial = window_rms(values, 0, min(initial_steps, T))
        final = window_rms(values, max(T - final_steps, 0), T)
        flag = ~(final <= np.maximum(initial, floors[group]))  # NaN -> True
        grown = flag if grown is None else grown | flag
    if grown is None:
        raise ValueError("no group errors given")
    return grown


def nees_high(nees: Float[ArrayF, "B T"], *, final_steps: int, quantile: float = 0.999, dof: int = NEES_DOF) -> Bool[ArrayB, "B"]:
    """``(B,)``: True where the NEES ``(B, T)`` exceeds the chi2(``dof``) ``quantile`` at every step
    of the last ``final_steps`` (steps without a value, NaN, do not count as exceeding)."""
    nees = np.asarray(nees, dtype=np.float64)
    tail = nees[:, max(nees.shape[1] - final_steps, 0):]
    threshold = chi2_upper(dof, quantile)
    return np.all(tail > threshold, axis=1) & (tail.shape[1] > 0)
