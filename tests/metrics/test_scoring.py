"""score_run on constructed runs: exact answers, sign flips, an exactly consistent filter."""

from __future__ import annotations

import numpy as np
import pytest

from fkn_bench.geometry import quaternion as quat
from fkn_bench.metrics import NEES_DOF, MetricSettings, average_statistic, score_run


def _truth(runs: int, steps: int, seed: int = 0) -> np.ndarray:
    """Constant-rate rotation, constant position, zero velocity (like ds1)."""
    rng = np.random.default_rng(seed)
    x = np.zeros((runs, steps, 13))
    q0 = quat.random_uniform(rng, runs)
    omega = np.array([0.02, 0.04, 0.06])
    t = np.arange(steps) * 0.1
    x[..., :4] = quat.multiply(quat.from_rotation_vector(t[:, None] * omega)[None], q0[:, None])
    x[..., 4:7] = [10.9, -6.7, 4.9]
    x[..., 7:10] = omega
    return x


def _apply_error(truth: np.ndarray, error: np.ndarray) -> np.ndarray:
    """Estimate whose 12-dim error (q_true = exp(dtheta/2) (x) q_est, rest truth - estimate) is ``error``."""
    estimate = truth.copy()
    estimate[..., :4] = quat.multiply(quat.conjugate(quat.from_rotation_vector(error[..., :3])), truth[..., :4])
    estimate[..., 4:] = truth[..., 4:] - error[..., 3:]
    return estimate


SETTINGS = MetricSettings(cut=10, settling_window=5, initial_steps=10, final_steps=20)


def test_perfect_estimates() -> None:
    truth = _truth(3, 60)
    P = np.broadcast_to(np.eye(12), (3, 60, 12, 12))
    scores = score_run(truth, truth.copy(), 0.1, error_covariances=P, settings=SETTINGS)
    assert np.allclose(scores.state_rmse, 0.0) and np.allclose(scores.component_rmse, 0.0, atol=1e-12)
    assert np.all(scores.settling_time == 0.0) and scores.settled.all()
    assert not scores.divergence.diverged.any()
    assert np.allclose(scores.nees_mean, 0.0)
    assert scores.scored_steps == 50 and scores.n_steps == 60
    assert scores.nis_sums is None and np.isnan(scores.nis_mean).all()


def test_constant_error_and_sign_flip() -> None:
    truth = _truth(2, 60)
    estimate = truth.copy()
    estimate[..., :4] *= -1.0  # sign flip: no attitude error
    estimate[..., 4:7] += [0.03, 0.0, 0.04]
    estimate[..., 7:10] += [0.001, 0.0, 0.0]
    scores = score_run(truth, estimate, 0.1, settings=SETTINGS)
    stats = scores.group_statistics
    assert np.allclose(stats["attitude"]["max"], 0.0, atol=1e-5)
    for name in ("rmse", "median", "p95", "max"):
        assert np.allclose(stats["position"][name], 0.05)
        assert np.allclose(stats["omega"][name], 0.001)
    assert np.allclose(scores.component_rmse[:, 4], 0.03) and np.allclose(scores.component_rmse[:, 6], 0.04)
    expected = np.sqrt((0.03**2 + 0.04**2 + 0.001**2) / 13)
    assert np.allclose(scores.state_rmse, expected)
    assert scores.settled.all()  # inside every default band from the start


def test_exactly_consistent_gaussian_filter_passes_nees() -> None:
    runs, steps = 50, 300
    rng = np.random.default_rng(4)
    truth = _truth(runs, steps, seed=5)
    sigma = np.array([0.02] * 3 + [0.05] * 3 + [0.002] * 3 + [0.001] * 3)
    A = rng.normal(size=(12, 12)) * 0.3 + np.eye(12)
    P = (A * sigma[:, None]) @ (A * sigma[:, None]).T  # correlated, positive definite
    error = rng.standard_normal((runs, steps, 12)) @ np.linalg.cholesky(P).T
    estimate = _apply_error(truth, error)
    scores = score_run(
        truth, estimate, 0.1, error_covariances=np.broadcast_to(P, (runs, steps, 12, 12)),
        settings=MetricSettings(cut=100),
    )
    anees = average_statistic(scores.nees_sums, NEES_DOF)
    lower, upper = float(anees.lower[0]), float(anees.upper[0])
    assert (lower, upper) == pytest.approx((10.68, 13.40), abs=0.006)
    assert lower <= anees.average <= upper
    assert anees.in_bounds_fraction >= 0.9
    assert not scores.divergence.nees_high.any() and not scores.divergence.cholesky_failed.any()


def test_overconfident_filter_is_flagged() -> None:
    runs, steps = 4, 300
    truth = _truth(runs, steps)
    error = np.random.default_rng(6).standard_normal((runs, steps, 12)) * 0.1
    P = np.broadcast_to(np.eye(12) * 1e-4, (runs, steps, 12, 12))  # NEES ~ 1200
    scores = score_run(truth, _apply_error(truth, error), 0.1, error_covariances=P, settings=SETTINGS)
    assert scores.divergence.nees_high.all() and scores.divergence.diverged.all()


def test_nan_and_indefinite_covariance_diverge() -> None:
    truth = _truth(3, 60)
    estimate = truth.copy()
    estimate[0, 30, 5] = np.nan
    P = np.array(np.broadcast_to(np.eye(12), (3, 60, 12, 12)))
    P[1, 40, 2, 2] = -1.0
    scores = score_run(truth, estimate, 0.1, error_covariances=P, settings=SETTINGS)
    assert scores.divergence.non_finite.tolist() == [True, False, False]
    assert scores.divergence.cholesky_failed.tolist() == [False, True, False]
    assert scores.divergence.diverged.tolist() == [True, True, False]


def test_nis_from_innovations() -> None:
    truth = _truth(2, 60)
    nu = np.ones((2, 60, 6))
    S = np.broadcast_to(np.eye(6) * 2.0, (2, 60, 6, 6))
    mask = np.zeros((2, 60), dtype=bool)
    mask[:, ::10] = True
    scores = score_run(truth, truth.copy(), 0.1, innovations=nu, innovation_covariances=S, innovation_mask=mask,
                       settings=SETTINGS)
    assert np.allclose(scores.nis_mean, 3.0)
    assert scores.nis_count.tolist() == [5.0, 5.0]  # steps 10..50 of the scored window


def test_empty_scored_window_is_rejected() -> None:
    truth = _truth(1, 50)
    with pytest.raises(ValueError, match="scored window"):
        score_run(truth, truth, 0.1, settings=MetricSettings(cut=50))


def test_settings_validation_and_round_trip() -> None:
    settings = MetricSettings(cut=7)
    assert MetricSettings.from_dict(settings.to_dict()) == settings
    assert hash(settings) == hash(MetricSettings(cut=7))
    with pytest.raises(ValueError):
        MetricSettings(settling_tolerances={"attitude": 1.0})
    with pytest.raises(ValueError):
        MetricSettings(cut=-1)
