"""Filter consistency: NEES, NIS, and their averages over Monte Carlo runs with chi-square bounds.

References: Y. Bar-Shalom, X. R. Li and T. Kirubarajan, *Estimation with Applications to Tracking
and Navigation*, Wiley (2001), section 5.4 (normalized estimation error squared, NEES
``e' P^-1 e``; normalized innovation squared, NIS ``nu' S^-1 nu``; average NEES over ``N``
independent runs, with ``N * ANEES ~ chi2(N n)`` for a consistent filter with an ``n``-dim error,
tested against a two-sided probability region). The 95% intervals of chi2 used as test
values: ``n = 12, N = 50: [10.68, 13.40]``; ``n = 3, N = 50: [2.36, 3.72]``; NIS
``n = 6, N = 50: [5.08, 7.00]``.

The NEES here is on the 12-dim error ``[dtheta, dr, dw, dv]``
(:func:`fkn_bench.metrics.errors.error_state`) with the estimator's 12x12 error covariance: the
additive EKF's 13x13 state covariance is singular along the quaternion
(:mod:`fkn_bench.filters.pose`). The NIS is
on the 6-dim pose innovation ``[dtheta, dr]`` that every estimator reports at its update steps.

Quantiles of chi2(k) are ``2 gammaincinv(k / 2, p)`` (what ``scipy.stats.chi2.ppf`` computes;
``scipy.special`` imports in a fraction of the time of ``scipy.stats``).

Across runs, values are summed per time step (:class:`StatisticSums`) so that sums from separate
batches of runs add up exactly (in a fixed order) before the average is taken.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import gammaincinv

from fkn_bench.types import ArrayB, ArrayF, Bool, Float

__all__ = [
    "NEES_DOF",
    "NIS_DOF",
    "QuadraticForm",
    "StatisticSums",
    "AverageStatistic",
    "normalized_squares",
    "positive_definite",
    "chi2_interval",
    "chi2_upper",
    "statistic_sums",
    "average_statistic",
]

NEES_DOF = 12
"""Degrees of freedom of the NEES on the 12-dim error state."""
NIS_DOF = 6
"""Degrees of freedom of the NIS on the 6-dim pose innovation."""


@dataclass(frozen=True, eq=False)
class QuadraticForm:
    """Normalized squares ``x' C^-1 x`` of a batch.

    Attributes:
        values: ``(B, T)``; NaN where masked out, where the inputs are not finite, or where the
            covariance is not positive definite.
        positive_definite: ``(B, T)`` True where the (finite) covariance has a Cholesky factor.
    """

    values: Float[ArrayF, "B T"]
    positive_definite: Bool[ArrayB, "B T"]


def positive_definite(covariances: Float[ArrayF, "... n n"]) -> Bool[ArrayB, "..."]:
    """``(..., n, n) -> (...)``: True where the matrix is finite and its Cholesky factorisation
    succeeds (LAPACK ``potrf`` through :func:`numpy.linalg.cholesky`)."""
    covariances = np.asarray(covariances, dtype=np.float64)
    shape = covariances.shape[:-2]
    flat = covariances.reshape(-1, *covariances.shape[-2:])
    ok = np.all(np.isfinite(flat), axis=(1, 2))
    if not ok.any():
        return ok.reshape(shape)
    try:
        np.linalg.cholesky(flat[ok])
    except np.linalg.LinAlgError:
        for i in np.flatnonzero(ok):  # rare path: find the matrices that fail
            try:
                np.linalg.cholesky(flat[i])
            except np.linalg.LinAlgError:
                ok[i] = False
    return ok.reshape(shape)


def normalized_squares(vectors: Float[ArrayF, "B T n"], covariances: Float[ArrayF, "B T n n"],
                       mask: Bool[ArrayB, "B T"] | None = None) -> QuadraticForm:
    """``x' C^-1 x`` for ``vectors (B, T, n)`` and ``covariances (B, T, n, n)`` where ``mask``
    ``(B, T)`` (default: everywhere). Use with the 12-dim error and error covariance for the NEES
    and with innovations and their covariances (``mask`` = update steps) for the NIS."""
    x = np.asarray(vectors, dtype=np.float64)
    C = np.asarray(covariances, dtype=np.float64)
    if x.ndim != 3 or C.shape != x.shape + (x.shape[-1],):
        raise ValueError(f"vectors (B, T, n) and covariances (B, T, n, n) do not match ({x.shape}, {C.shape})")
    m = np.ones(x.shape[:2], dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    if m.shape != x.shape[:2]:
        raise ValueError(f"mask must have shape {x.shape[:2]} (got {m.shape})")
    pd = np.zeros(x.shape[:2], dtype=bool)
    pd[m] = positive_definite(C[m])
    use = m & pd & np.all(np.isfinite(x), axis=-1)
    values = np.full(x.shape[:2], np.nan)
    if use.any():
        xu, Cu = x[use], C[use]
        try:
            values[use] = np.einsum("ki,ki->k", xu, np.linalg.solve(Cu, xu[..., None])[..., 0])
        except np.linalg.LinAlgError:  # one matrix that factorised but is singular to working precision
            forms = np.full(len(xu), np.nan)  # (LAPACK's LU fails where Cholesky passed): that one has no NEES,
            for k in range(len(xu)):          # and counts as not positive definite, like a failed Cholesky
                try:
                    forms[k] = xu[k] @ np.linalg.solve(Cu[k], xu[k])
                except np.linalg.LinAlgError:
                    pass
            values[use] = forms
            pd[use] &= np.isfinite(forms)
    return QuadraticForm(values=values, positive_definite=pd | ~m)


def _chi2_ppf(probability: float, dof: ArrayF) -> ArrayF:
    dof = np.asarray(dof, dtype=np.float64)
    unique, where = np.unique(dof, return_inverse=True)  # per-step run counts repeat: one quantile each
    return (2.0 * gammaincinv(0.5 * unique, probability))[where].reshape(dof.shape)


def chi2_interval(dof: int, runs: int | ArrayF, confidence: float = 0.95) -> tuple[ArrayF, ArrayF]:
    """Two-sided ``confidence`` interval of the average of ``runs`` independent chi2(``dof``)
    values: ``[chi2.ppf((1-c)/2, runs dof), chi2.ppf((1+c)/2, runs dof)] / runs``
    (Bar-Shalom et al. 2001, sec. 5.4.2). ``runs`` may be an array (per time step); where it is
    0 the bounds are NaN."""
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1) (got {confidence})")
    n = np.asarray(runs, dtype=np.float64)
    safe = np.where(n > 0, n, 1.0)
    lower = np.where(n > 0, _chi2_ppf(0.5 * (1.0 - confidence), safe * dof) / safe, np.nan)
    upper = np.where(n > 0, _chi2_ppf(0.5 * (1.0 + confidence), safe * dof) / safe, np.nan)
    return lower, upper


def chi2_upper(dof: int, probability: float) -> float:
    """The ``probability`` quantile of chi2(``dof``), e.g. 32.91 for ``dof = 12, p = 0.999``."""
    return float(_chi2_ppf(probability, dof))


@dataclass(frozen=True, eq=False)
class StatisticSums:
    """Per-time-step sums of a normalized statistic over runs, ``sum (T,)`` and ``count (T,)``
    (the number of runs with a value at that step). Sums of disjoint sets of runs add."""

    sum: Float[ArrayF, "T"]
    count: Float[ArrayF, "T"]

    def __add__(self, other: StatisticSums) -> StatisticSums:
        if self.sum.shape != other.sum.shape:
            raise ValueError(f"cannot add sums over {self.sum.shape} and {other.sum.shape} steps")
        return StatisticSums(self.sum + other.sum, self.count + other.count)


def statistic_sums(values: Float[ArrayF, "B T"]) -> StatisticSums:
    """Sum ``values (B, T)`` over runs per step, skipping NaN (not-a-value steps)."""
    values = np.asarray(values, dtype=np.float64)
    present = np.isfinite(values)
    return StatisticSums(
        sum=np.sum(np.where(present, values, 0.0), axis=0),
        count=np.sum(present, axis=0).astype(np.float64),
    )


@dataclass(frozen=True, eq=False)
class AverageStatistic:
    """The average of a normalized statistic over runs and its chi-square test.

    Attributes:
        dof: degrees of freedom of one value.
        per_step: average over runs at each step, ``(T,)`` (NaN where no run has a value).
        lower, upper: two-sided interval per step for that step's number of runs, ``(T,)``.
        in_bounds_fraction: share of the steps with values whose average lies inside its interval.
        average: the average over all values (all runs and steps).
        values: the number of values averaged.
    """

    dof: int
    per_step: Float[ArrayF, "T"]
    lower: Float[ArrayF, "T"]
    upper: Float[ArrayF, "T"]
    in_bounds_fraction: float
    average: float
    values: int


def average_statistic(sums: StatisticSums, dof: int, confidence: float = 0.95) -> AverageStatistic:
    """Average NEES (ANEES) or NIS over runs with its per-step ``confidence`` interval.

    For ``N`` runs of a consistent filter ``N * ANEES_k ~ chi2(N n)`` at every step ``k``
    (Bar-Shalom et al. 2001, eq. 5.4.2-3); about ``confidence`` of the steps then fall inside
    the interval."""
    count = np.asarray(sums.count, dtype=np.float64)
    has = count > 0
    per_step = np.where(has, sums.sum / np.where(has, count, 1.0), np.nan)
    lower, upper = chi2_interval(dof, count, confidence)
    inside = has & (per_step >= lower) & (per_step <= upper)
    n_steps = int(has.sum())
    total = float(count.sum())
    return AverageStatistic(
        dof=dof,
        per_step=per_step,
        lower=lower,
        upper=upper,
        in_bounds_fraction=float(inside.sum() / n_steps) if n_steps else float("nan"),
        average=float(np.sum(sums.sum) / total) if total else float("nan"),
        values=int(total),
    )
