"""The variants' step functions on numpy arrays (the online path) equal the torch batched run
to 1e-12 over long sequences, are pure, and keep the model's rules."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fkn_bench.envs import generate_episodes
from fkn_bench.filters import VARIANTS, ExtendedKalmanFilter, FilterState, make_filter
from fkn_bench.models import PoseTwistModel
from fkn_bench.linalg import _CONSTANTS
from fkn_bench.scenarios import get_scenario

DT = 0.1
_ONE = np.ones(1, dtype=bool)


@pytest.mark.parametrize("variant_name", sorted(VARIANTS))
@pytest.mark.parametrize("every", [1, 10])
def test_numpy_steps_equal_the_torch_run_over_a_long_sequence(variant_name: str, every: int) -> None:
    """2000 steps of ds1-flips (sign flips, outliers) with a measurement every step or every
    10 steps, NaN measurements inside the mask and non-unit quaternions."""
    scenario = get_scenario("ds1-flips", measurement_every=every)
    episodes = generate_episodes(scenario, [5], split="train").window(0, 2000 if variant_name == "ekf" else 600)
    z, valid = episodes.measurements[0].copy(), episodes.valid[0].copy()
    rng = np.random.default_rng(every)
    z[valid, :4] *= rng.uniform(0.5, 2.0, (valid.sum(), 1))
    bad = rng.choice(np.flatnonzero(valid), 20, replace=False)
    z[bad, rng.integers(0, 7, 20)] = np.nan
    variant = make_filter(variant_name)
    noise = variant.layout.default_noise()
    Q, R, P0 = (m.numpy() for m in (noise.process, noise.measurement, noise.initial))
    result = variant.run(noise, torch.from_numpy(z)[None], torch.from_numpy(valid)[None], dt=DT)
    state, initialised = None, False
    worst_mean = worst_cov = 0.0
    for t in range(len(z)):
        if state is not None:
            state = variant.predict(state, Q, DT)
        measurement, usable = variant.model.sanitize(z[t][None], valid[t : t + 1])
        if usable[0]:
            if not initialised:
                state, initialised = variant.initial_state(measurement, P0), True
            else:
                state, nu, S = variant.update(state, measurement, R)
                np.testing.assert_allclose(nu[0], result.innovations[0, t].numpy(), rtol=0, atol=1e-12)
                np.testing.assert_allclose(S[0], result.innovation_covariances[0, t].numpy(), rtol=0, atol=1e-12)
        if state is not None:
            worst_mean = max(worst_mean, np.abs(state.mean[0] - result.means[0, t].numpy()).max())
            worst_cov = max(worst_cov, np.abs(state.covariance[0] - result.covariances[0, t].numpy()).max())
    assert initialised
    assert worst_mean < 1e-12 and worst_cov < 1e-12, (worst_mean, worst_cov)


def test_predict_and_update_are_pure_and_match_the_model() -> None:
    rng = np.random.default_rng(0)
    x = rng.standard_normal(13)
    x[:4] /= np.linalg.norm(x[:4])
    L = rng.standard_normal((13, 13))
    P = L @ L.T
    Q = np.diag(rng.uniform(1e-6, 1e-4, 13))
    R = np.diag(rng.uniform(1e-3, 1e-2, 7))
    originals = [a.copy() for a in (x, P, Q, R)]
    ekf = ExtendedKalmanFilter()
    predicted = ekf.predict(FilterState(x[None], P[None]), Q, 0.37)
    x_pred, P_pred = predicted.mean[0], predicted.covariance[0]
    model = PoseTwistModel()
    np.testing.assert_allclose(x_pred, model.predict(torch.from_numpy(x)[None], 0.37)[0].numpy(), rtol=0, atol=1e-15)
    F = model.jacobian(torch.from_numpy(x)[None], 0.37)[0].numpy()
    np.testing.assert_allclose(P_pred, F @ P @ F.T + Q, rtol=0, atol=1e-12)
    z = np.concatenate((-x[:4], x[4:7] + 0.1))  # opposite sign: aligned before the innovation
    posterior, nu, S = ekf.update(predicted, z[None], R)
    x_post, P_post = posterior.mean[0], posterior.covariance[0]
    np.testing.assert_allclose(nu[0, :4], x[:4] - x_pred[:4], rtol=0, atol=1e-15)
    assert np.linalg.norm(x_post[:4]) == pytest.approx(1.0, abs=1e-15)
    # exact: P_post is symmetrised, 0.5 (M + M^T), the same sum at [i, j] and [j, i]
    np.testing.assert_array_equal(P_post, P_post.T)
    for original, now in zip(originals, (x, P, Q, R)):
        np.testing.assert_array_equal(original, now)  # inputs untouched (exact: no arithmetic on them)
    state, _, _ = ekf.update(FilterState(torch.from_numpy(x_pred)[None], torch.from_numpy(P_pred)[None]), torch.from_numpy(z)[None], torch.from_numpy(R))
    np.testing.assert_allclose(x_post, state.mean[0].numpy(), rtol=0, atol=1e-13)
    np.testing.assert_allclose(P_post, state.covariance[0].numpy(), rtol=0, atol=1e-12)


def test_numpy_update_refuses_an_indefinite_innovation_covariance() -> None:
    x = np.zeros((1, 13))
    x[0, 0] = 1.0
    with pytest.raises(np.linalg.LinAlgError, match="not positive definite"):
        ExtendedKalmanFilter().update(FilterState(x, -np.eye(13)[None]), np.array([[1.0, 0, 0, 0, 0, 0, 0]]), np.zeros((7, 7)))


def _sanitized(z: np.ndarray) -> np.ndarray | None:
    out, usable = PoseTwistModel().sanitize(z[None], _ONE)
    return out[0] if usable[0] else None


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
def test_numpy_sanitize() -> None:
    np.testing.assert_allclose(_sanitized(np.array([0.0, 3.0, 0.0, 4.0, 1.0, 2.0, 3.0])), [0, 0.6, 0, 0.8, 1, 2, 3])
    assert _sanitized(np.array([np.nan] + [0.0] * 6)) is None
    assert _sanitized(np.array([1.0, 0, 0, 0, np.inf, 0, 0])) is None
    assert _sanitized(np.array([0.0, 0, 0, 0, 1, 1, 1])) is None
    assert _sanitized(np.array([1e-7, 0, 0, 0, 1, 1, 1])) is None
    assert _sanitized(np.array([1e160, 1e160, 0, 0, 1, 1, 1])) is None  # |q|^2 overflows
    z = np.array([2.0, 0, 0, 0, 1, 1, 1])
    _sanitized(z)
    assert z[0] == 2.0  # not modified in place


def test_constant_cache_is_bounded() -> None:
    x = PoseTwistModel().initial_state(np.arange(7.0)[None])
    np.testing.assert_array_equal(x[0], np.concatenate((np.arange(7.0), np.zeros(6))))  # exact: copied
    for k in range(400):  # irregular steps must not grow the cache without bound
        PoseTwistModel().transition(x, 0.1 + k * 1e-3)
    assert len(_CONSTANTS) <= 256
