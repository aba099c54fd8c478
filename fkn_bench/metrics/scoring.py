"""All metrics of one batch of runs (estimates against truth), with their settings.

:func:`score_run` takes plain arrays, never an estimator: truth and estimated states, optionally
the 12x12 error covariances and the 6-dim pose innovations with their covariances. It returns
:class:`RunScores`, one value per run (sequence) for every metric, plus per-step NEES/NIS sums
that batches of runs pool into the Monte Carlo averages (ANEES, ANIS).

Windows (``T`` steps per run, :class:`MetricSettings`):

* the *scored window* ``[cut, T)`` (default ``cut = 100``, the paper's loss cut: the first 100
  steps of a sequence are the filter's transient) gives the RMSEs, error statistics, NEES and NIS;
* settling times use the whole run, counted from its first step (the transient is what they
  measure);
* divergence compares the first ``initial_steps`` with the last ``final_steps`` of the run and
  checks finiteness and Cholesky factorisations over the scored window.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fkn_bench.metrics.accuracy import component_rmse, magnitude_statistics, state_rmse
from fkn_bench.metrics.consistency import StatisticSums, normalized_squares, statistic_sums
from fkn_bench.metrics.errors import GROUPS, component_errors, error_state, group_errors
from fkn_bench.metrics.settling import DEFAULT_PEAK_FRACTION, DEFAULT_TOLERANCES, SettlingResult, settling_time
from fkn_bench.metrics.stability import DEFAULT_GROWTH_FLOORS, DivergenceFlags, error_growth, nees_high
from fkn_bench.types import ERROR_DIM, POSE_ERROR_DIM, STATE_DIM, ArrayB, ArrayF, Bool, Float

__all__ = ["MetricSettings", "RunScores", "score_run"]


@dataclass(frozen=True)
class MetricSettings:
    """Settings of every metric (steps are samples of the run, ``dt`` apart).

    Attributes:
        cut: first scored step (the paper's loss cut, 100).
        settling_window: smoothing window of the settling test, steps (100 = 10 s at 10 Hz: one
            measurement period of ds1-gap100, ten of ds1).
        settling_tolerances: absolute band per group (:data:`fkn_bench.metrics.settling.DEFAULT_TOLERANCES`).
        peak_fraction: band fraction of the peak error (0.02).
        initial_steps, final_steps: divergence windows at the start and end of a run.
        growth_floors: per-group floors of the error-growth test
            (:data:`fkn_bench.metrics.stability.DEFAULT_GROWTH_FLOORS`).
        nees_quantile: chi2 quantile of the NEES divergence test (0.999).
        confidence: two-sided probability of the ANEES/ANIS intervals (0.95).
    """

    cut: int = 100
    settling_window: int = 100
    settling_tolerances: Mapping[str, float] = field(default_factory=lambda: dict(DEFAULT_TOLERANCES))
    peak_fraction: float = DEFAULT_PEAK_FRACTION
    initial_steps: int = 100
    final_steps: int = 200
    growth_floors: Mapping[str, float] = field(default_factory=lambda: dict(DEFAULT_GROWTH_FLOORS))
    nees_quantile: float = 0.999
    confidence: float = 0.95

    def __post_init__(self) -> None:
        if not isinstance(self.cut, int) or self.cut < 0:
            raise ValueError(f"cut must be an integer >= 0 (got {self.cut!r})")
        for name in ("settling_window", "initial_steps", "final_steps"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise ValueError(f"{name} must be an integer >= 1 (got {getattr(self, name)!r})")
        for name in ("settling_tolerances", "growth_floors"):
            value = dict(getattr(self, name))
            if set(value) != set(GROUPS):
                raise ValueError(f"{name} needs one value for each of {', '.join(GROUPS)} (got {sorted(value)})")
            object.__setattr__(self, name, {g: float(value[g]) for g in GROUPS})
        if not 0.0 < self.nees_quantile < 1.0 or not 0.0 < self.confidence < 1.0:
            raise ValueError("nees_quantile and confidence must be in (0, 1)")

    def __hash__(self) -> int:  # the dict fields would make the generated hash fail
        return hash(json.dumps(self.to_dict(), sort_keys=True))

    def to_dict(self) -> dict[str, Any]:
        """JSON-compatible dict (for provenance and result keys)."""
        return {f.name: (dict(v) if isinstance(v := getattr(self, f.name), Mapping) else v) for f in dataclasses.fields(self)}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> MetricSettings:
        return cls(**dict(data))


@dataclass(frozen=True, eq=False)
class RunScores:
    """Per-run metrics of a batch of ``B`` runs (every array is ``(B, ...)``).

    Attributes:
        n_steps, scored_steps: run length and scored-window length.
        component_rmse: ``(B, 13)`` RMSE per state component (quaternion sign-aligned).
        state_rmse: ``(B,)`` the 13-state RMSE (primary score).
        group_statistics: ``{group: {"rmse"|"median"|"p95"|"max": (B,)}}`` of the group error
            magnitudes (deg, m, rad/s, m/s).
        settling: ``{group: SettlingResult}``.
        settling_time, settled: ``(B,)`` the latest group settling time and whether every group
            settled.
        nees_mean, nis_mean: ``(B,)`` average NEES / NIS per run (NaN when not available).
        nis_count: ``(B,)`` number of NIS values per run.
        nees_sums, nis_sums: per-step sums over the batch (None when not available).
        divergence: :class:`DivergenceFlags`.
    """

    n_steps: int
    scored_steps: int
    component_rmse: Float[ArrayF, "B 13"]
    state_rmse: Float[ArrayF, "B"]
    group_statistics: dict[str, dict[str, Float[ArrayF, "B"]]]
    settling: dict[str, SettlingResult]
    settling_time: Float[ArrayF, "B"]
    settled: Bool[ArrayB, "B"]
    nees_mean: Float[ArrayF, "B"]
    nis_mean: Float[ArrayF, "B"]
    nis_count: Float[ArrayF, "B"]
    nees_sums: StatisticSums | None
    nis_sums: StatisticSums | None
    divergence: DivergenceFlags

    @property
    def batch_size(self) -> int:
        return int(self.state_rmse.shape[0])


def _row_mean(values: ArrayF) -> ArrayF:
    present = np.isfinite(values)
    count = present.sum(axis=1)
    total = np.where(present, values, 0.0).sum(axis=1)
    return np.where(count > 0, total / np.maximum(count, 1), np.nan)


def score_run(
    truth: Float[ArrayF, "B T 13"],
    means: Float[ArrayF, "B T 13"],
    dt: float,
    *,
    error_covariances: Float[ArrayF, "B T 12 12"] | None = None,
    innovations: Float[ArrayF, "B T 6"] | None = None,
    innovation_covariances: Float[ArrayF, "B T 6 6"] | None = None,
    innovation_mask: Bool[ArrayB, "B T"] | None = None,
    settings: MetricSettings | None = None,
) -> RunScores:
    """Score estimates against the truth (see module docstring).

    Args:
        truth, means: true and estimated states ``(B, T, 13)``.
        dt: sample interval, s.
        error_covariances: ``(B, T, 12, 12)`` covariance of the 12-dim error (NEES, Cholesky test).
        innovations, innovation_covariances, innovation_mask: ``(B, T, 6)``, ``(B, T, 6, 6)`` and
            ``(B, T)`` pose innovations at update steps (NIS).
        settings: :class:`MetricSettings` (defaults when None).
    """
    settings = settings or MetricSettings()
    truth = np.asarray(truth, dtype=np.float64)
    means = np.asarray(means, dtype=np.float64)
    if truth.ndim != 3 or truth.shape != means.shape or truth.shape[-1] != STATE_DIM:
        raise ValueError(f"truth and means must have the same shape (B, T, 13) (got {truth.shape}, {means.shape})")
    B, T = truth.shape[:2]
    cut = settings.cut
    if cut >= T:
        raise ValueError(f"the scored window [cut={cut}, T={T}) is empty: runs need more than {cut} steps")
    scored = slice(cut, T)

    errors = component_errors(truth, means)
    magnitudes = group_errors(truth, means)
    comp = component_rmse(errors[:, scored])
    total = state_rmse(errors[:, scored])
    stats = {g: magnitude_statistics(magnitudes[g][:, scored]) for g in GROUPS}

    settling = {
        g: settling_time(magnitudes[g], dt, tolerance=settings.settling_tolerances[g],
                         window=settings.settling_window, peak_fraction=settings.peak_fraction)
        for g in GROUPS
    }
    settling_all = np.max(np.stack([settling[g].time for g in GROUPS]), axis=0)
    settled_all = np.all(np.stack([settling[g].settled for g in GROUPS]), axis=0)

    non_finite = ~np.all(np.isfinite(means[:, scored]), axis=(1, 2))
    cholesky_failed = np.zeros(B, dtype=bool)
    nees_values = np.full((B, T - cut), np.nan)
    nees_sums = None
    if error_covariances is not None:
        P = np.asarray(error_covariances, dtype=np.float64)
        if P.shape != (B, T, ERROR_DIM, ERROR_DIM):
            raise ValueError(f"error_covariances must have shape {(B, T, ERROR_DIM, ERROR_DIM)} (got {P.shape})")
        finite = np.all(np.isfinite(P[:, scored]), axis=(2, 3))
        non_finite |= ~np.all(finite, axis=1)
        nees = normalized_squares(error_state(truth[:, scored], means[:, scored]), P[:, scored])
        cholesky_failed = ~np.all(nees.positive_definite | ~finite, axis=1)
        nees_values = nees.values
        nees_sums = statistic_sums(nees_values)

    nis_values = np.full((B, T - cut), np.nan)
    nis_sums = None
    if innovations is not None and innovation_covariances is not None:
        nu = np.asarray(innovations, dtype=np.float64)
        S = np.asarray(innovation_covariances, dtype=np.float64)
        if nu.shape != (B, T, POSE_ERROR_DIM) or S.shape != (B, T, POSE_ERROR_DIM, POSE_ERROR_DIM):
            raise ValueError(f"innovations must be (B, T, 6) with covariances (B, T, 6, 6) (got {nu.shape}, {S.shape})")
        mask = np.ones((B, T), dtype=bool) if innovation_mask is None else np.asarray(innovation_mask, dtype=bool)
        nis_values = normalized_squares(nu[:, scored], S[:, scored], mask[:, scored]).values
        nis_sums = statistic_sums(nis_values)

    growth = error_growth(magnitudes, initial_steps=settings.initial_steps,
                          final_steps=settings.final_steps, floors=settings.growth_floors)
    high = nees_high(nees_values, final_steps=settings.final_steps, quantile=settings.nees_quantile)
    divergence = DivergenceFlags(non_finite, cholesky_failed, growth, high)
    return RunScores(
        n_steps=T,
        scored_steps=T - cut,
        component_rmse=comp,
        state_rmse=total,
        group_statistics=stats,
        settling=settling,
        settling_time=settling_all,
        settled=settled_all,
        nees_mean=_row_mean(nees_values),
        nis_mean=_row_mean(nis_values),
        nis_count=np.isfinite(nis_values).sum(axis=1).astype(np.float64),
        nees_sums=nees_sums,
        nis_sums=nis_sums,
        divergence=divergence,
    )

