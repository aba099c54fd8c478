"""Settling time: the first time after which an error stays inside a band for the rest of a run.

Definition (the settling time of control engineering, e.g. Ogata, Modern Control Engineering,
2010, with the band ``max(abs tol, 2% of peak)``):

1. The error magnitude ``e_k`` of a state group (e.g. the attitude error angle) is smoothed by a
   centred moving root mean square over ``window`` steps (``s_k = sqrt(mean(e_j^2))`` for
   ``|j - k| <= window // 2``, the window shrinking at the ends). Raw errors of a filter fed
   noisy measurements spike at every update; smoothing makes "stays inside" a statement about
   the error *level*, not about single noisy samples. ``window = 1`` disables it.
2. The band is ``max(tolerance, peak_fraction * max_k s_k)``: an absolute tolerance per group
   (see :data:`DEFAULT_TOLERANCES`), widened for runs whose transient is so large that 2% of its
   peak exceeds the tolerance.
3. The settling time is ``k_s * dt`` (s, counted from the start of the run, step 0) for the
   smallest ``k_s`` with ``s_k <= band`` for every ``k >= k_s``. A run that ends outside the band
   never settles: it is flagged (``settled = False``) and given the run length ``T * dt``.
   NaN counts as outside the band.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from fkn_bench.types import ArrayB, ArrayF, Bool, Float

__all__ = [
    "DEFAULT_TOLERANCES",
    "DEFAULT_PEAK_FRACTION",
    "SettlingResult",
    "moving_rms",
    "settling_band",
    "settling_time",
]

DEFAULT_TOLERANCES: Mapping[str, float] = {
    "attitude": 10.0,  # deg
    "position": 0.1,  # m
    "omega": 0.03,  # rad/s
    "velocity": 0.005,  # m/s
}
"""Absolute settling tolerances per state group (units of
:data:`fkn_bench.metrics.errors.GROUP_UNITS`), chosen for ds1 (noise 0.1 rad / 0.1 m per axis,
rate 0.075 rad/s), relative to the manual EKF's RMS error over the final 20 s of ds1's test
runs (5.3 deg, 0.038 m, 0.015 rad/s, 0.0013 m/s, 20 seeds): attitude 10 deg (the raw
measurement's error level, sqrt(3) x 0.1 rad = 9.9 deg; about twice that final error), position
0.1 m (the per-axis measurement noise; about 2.5x), angular rate 0.03 rad/s (40% of the true rate;
twice) and velocity 0.005 m/s (about 4x). A filter that settles is one whose error level has come
down to, and stays at, a few times a reasonable filter's steady state. The bands are absolute:
on noisier scenarios (ds1-noise5x) an estimator may never settle, and that is reported."""

DEFAULT_PEAK_FRACTION = 0.02
"""Band fraction of the peak (smoothed) error: the 2% criterion of control engineering."""


@dataclass(frozen=True, eq=False)
class SettlingResult:
    """Settling of a batch of runs.

    Attributes:
        time: settling time per run, s, ``(B,)`` (the run length ``T * dt`` where not settled).
        settled: ``(B,)`` False for runs that end outside the band.
        band: the band used per run, ``(B,)``, in the error's units.
    """

    time: Float[ArrayF, "B"]
    settled: Bool[ArrayB, "B"]
    band: Float[ArrayF, "B"]


def moving_rms(errors: Float[ArrayF, "B T"], window: int) -> Float[ArrayF, "B T"]:
    """Centred moving root mean square over ``window`` steps along the last axis, ``(B, T)``;
    the window shrinks at both ends (it covers ``k - window // 2 .. k + window // 2``)."""
    errors = np.asarray(errors, dtype=np.float64)
    if errors.ndim != 2:
        raise ValueError(f"errors must have shape (B, T) (got {errors.shape})")
    if int(window) < 1:
        raise ValueError(f"window must be >= 1 step (got {window})")
    if window == 1:
        return np.abs(errors)
    T = errors.shape[1]
    half = int(window) // 2
    cumulative = np.concatenate((np.zeros((errors.shape[0], 1)), np.cumsum(np.square(errors), axis=1)), axis=1)
    index = np.arange(T)
    lo = np.clip(index - half, 0, T)
    hi = np.clip(index + half + 1, 0, T)
    mean_square = (cumulative[:, hi] - cumulative[:, lo]) / (hi - lo)
    return np.sqrt(np.maximum(mean_square, 0.0))


def settling_band(smoothed: Float[ArrayF, "B T"], tolerance: float,
                  peak_fraction: float = DEFAULT_PEAK_FRACTION) -> Float[ArrayF, "B"]:
    """Band per run ``max(tolerance, peak_fraction * peak)``, ``(B, T) -> (B,)``; the peak
    ignores NaN (a run that is NaN throughout gets the tolerance)."""
    smoothed = np.asarray(smoothed, dtype=np.float64)
    if tolerance < 0 or not np.isfinite(tolerance):
        raise ValueError(f"tolerance must be a finite number >= 0 (got {tolerance})")
    finite = np.where(np.isfinite(smoothed), smoothed, -np.inf)
    peak = np.max(finite, axis=1) if smoothed.shape[1] else np.full(smoothed.shape[0], -np.inf)
    return np.maximum(float(tolerance), peak_fraction * np.maximum(peak, 0.0))


def settling_time(
    errors: Float[ArrayF, "B T"],
    dt: float,
    *,
    tolerance: float,
    window: int = 1,
    peak_fraction: float = DEFAULT_PEAK_FRACTION,
) -> SettlingResult:
    """Settling time of error magnitudes ``(B, T)`` sampled every ``dt`` s (module docstring)."""
    errors = np.asarray(errors, dtype=np.float64)
    if errors.ndim != 2 or errors.shape[1] == 0:
        raise ValueError(f"errors must have shape (B, T) with T >= 1 (got {errors.shape})")
    if not np.isfinite(dt) or dt <= 0:
        raise ValueError(f"dt must be a finite number > 0 (got {dt})")
    smoothed = moving_rms(errors, window)
    band = settling_band(smoothed, tolerance, peak_fraction)
    outside = ~(smoothed <= band[:, None])  # NaN is outside
    T = errors.shape[1]
    any_outside = outside.any(axis=1)
    last_outside = T - 1 - np.argmax(outside[:, ::-1], axis=1)
    first_settled = np.where(any_outside, last_outside + 1, 0)
    settled = first_settled < T
    return SettlingResult(time=first_settled * float(dt), settled=settled, band=band)
