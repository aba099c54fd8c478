"""NEES, NIS, ANEES and chi-square bounds (Bar-Shalom, Li & Kirubarajan 2001, sec. 5.4)."""

from __future__ import annotations

import numpy as np
import pytest

from fkn_bench.metrics import (
    StatisticSums,
    average_statistic,
    chi2_interval,
    chi2_upper,
    normalized_squares,
    positive_definite,
    statistic_sums,
)


@pytest.mark.parametrize(
    ("dof", "runs", "lower", "upper"),
    [(12, 50, 10.68, 13.40), (3, 50, 2.36, 3.72), (6, 50, 5.08, 7.00)],
)
def test_reference_intervals(dof: int, runs: int, lower: float, upper: float) -> None:
    lo, hi = chi2_interval(dof, runs, 0.95)
    assert float(lo) == pytest.approx(lower, abs=0.006)
    assert float(hi) == pytest.approx(upper, abs=0.006)


def test_interval_for_zero_runs_is_nan() -> None:
    lo, hi = chi2_interval(12, np.array([0, 10]))
    assert np.isnan(lo[0]) and np.isnan(hi[0]) and np.isfinite(lo[1])


def test_upper_quantile() -> None:
    assert chi2_upper(12, 0.999) == pytest.approx(32.909, abs=1e-3)


def _random_covariances(rng: np.random.Generator, shape: tuple[int, ...], n: int) -> np.ndarray:
    A = rng.normal(size=shape + (n, n))
    return A @ np.swapaxes(A, -1, -2) + 0.5 * np.eye(n)


def _consistent_run(rng: np.random.Generator, runs: int, steps: int, n: int, scale: float = 1.0):
    P = _random_covariances(rng, (runs, steps), n)
    L = np.linalg.cholesky(P)
    errors = np.einsum("btij,btj->bti", L, rng.standard_normal((runs, steps, n)))
    return errors, scale * P


def test_exactly_consistent_gaussian_filter_passes() -> None:
    rng = np.random.default_rng(1)
    errors, P = _consistent_run(rng, runs=50, steps=400, n=12)
    nees = normalized_squares(errors, P)
    assert nees.positive_definite.all()
    result = average_statistic(statistic_sums(nees.values), 12)
    assert result.average == pytest.approx(12.0, rel=0.02)
    assert 0.90 <= result.in_bounds_fraction <= 0.99  # ~95% of the steps
    assert result.values == 50 * 400
    assert float(result.lower[0]) == pytest.approx(10.68, abs=0.006)


def test_overconfident_filter_fails() -> None:
    rng = np.random.default_rng(2)
    errors, P = _consistent_run(rng, runs=50, steps=200, n=12, scale=0.5)  # claims half the variance
    result = average_statistic(statistic_sums(normalized_squares(errors, P).values), 12)
    assert result.average == pytest.approx(24.0, rel=0.05)
    assert result.in_bounds_fraction < 0.01


def test_nees_of_a_known_case() -> None:
    errors = np.array([[[1.0, 2.0]]])
    P = np.array([[[[1.0, 0.0], [0.0, 4.0]]]])
    assert normalized_squares(errors, P).values[0, 0] == pytest.approx(2.0)


def test_nis_only_where_masked_and_sums_add() -> None:
    rng = np.random.default_rng(3)
    nu, S = _consistent_run(rng, runs=4, steps=30, n=6)
    mask = np.zeros((4, 30), dtype=bool)
    mask[:, ::10] = True
    nis = normalized_squares(nu, S, mask).values
    assert np.isfinite(nis[mask]).all() and np.isnan(nis[~mask]).all()
    whole = statistic_sums(nis)
    parts = statistic_sums(nis[:2]) + statistic_sums(nis[2:])
    assert np.array_equal(whole.count, parts.count) and np.allclose(whole.sum, parts.sum)
    assert whole.count.tolist() == [4.0 if k % 10 == 0 else 0.0 for k in range(30)]
    result = average_statistic(whole, 6)
    assert np.isnan(result.per_step[1]) and np.isfinite(result.per_step[0])


def test_failed_cholesky_is_detected() -> None:
    P = np.tile(np.eye(3), (1, 3, 1, 1))
    P[0, 1] = np.diag([1.0, -1.0, 1.0])  # indefinite
    P[0, 2, 0, 0] = np.nan
    nees = normalized_squares(np.ones((1, 3, 3)), P)
    assert nees.positive_definite.tolist() == [[True, False, False]]
    assert np.isnan(nees.values[0, 1:]).all() and nees.values[0, 0] == pytest.approx(3.0)
    assert positive_definite(np.eye(2)[None]).tolist() == [True]


def test_sums_of_different_lengths_do_not_add() -> None:
    with pytest.raises(ValueError):
        StatisticSums(np.zeros(3), np.zeros(3)) + StatisticSums(np.zeros(4), np.zeros(4))


def test_quantiles_match_scipy_stats() -> None:
    from scipy.stats import chi2

    for dof, runs in ((12, 1), (12, 20), (6, 37), (3, 1000)):
        lo, hi = chi2_interval(dof, runs, 0.95)
        assert float(lo) == pytest.approx(chi2.ppf(0.025, dof * runs) / runs, rel=1e-12)
        assert float(hi) == pytest.approx(chi2.ppf(0.975, dof * runs) / runs, rel=1e-12)
    assert chi2_upper(12, 0.999) == pytest.approx(chi2.ppf(0.999, 12), rel=1e-12)


def test_a_covariance_singular_to_working_precision_has_no_nees_and_counts_as_not_positive_definite(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Recursive KalmanNet's error covariance on spin-flips reached 6e14 beside 8e-4 (condition
    ~1e18): Cholesky passes, LAPACK's LU solve raises "Singular matrix", and one such step made
    the whole leaderboard cell fail. Now that step has no NEES and counts as not positive definite
    (a lost track's flag), and every other step is scored."""
    real_solve = np.linalg.solve

    def solve(a, b):  # noqa: ANN001, ANN202 - LU failing on the marked matrix, as LAPACK did
        if np.asarray(a).ndim == 3 or np.asarray(a)[0, 0] == 7.0:
            raise np.linalg.LinAlgError("Singular matrix")
        return real_solve(a, b)

    monkeypatch.setattr(np.linalg, "solve", solve)
    P = np.tile(np.eye(3), (1, 4, 1, 1))
    P[0, 2, 0, 0] = 7.0
    result = normalized_squares(np.ones((1, 4, 3)), P)
    np.testing.assert_array_equal(result.values, [[3.0, 3.0, np.nan, 3.0]])
    np.testing.assert_array_equal(result.positive_definite, [[True, True, False, True]])
