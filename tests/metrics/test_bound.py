"""The posterior Cramér-Rao bound: the Kalman filter's covariance on a linear-Gaussian model, and
what a scenario's prior, noise, schedule and inertia do to it."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from fkn_bench.filters.linear import linear_kalman_filter
from fkn_bench.metrics.bound import covariance_recursion, efficiency, posterior_bound
from fkn_bench.scenarios import get_scenario

DT = 0.1


def test_recursion_is_the_kalman_filter_covariance_on_a_linear_gaussian_model() -> None:
    rng = np.random.default_rng(0)
    A = np.eye(4)
    A[0, 2] = A[1, 3] = DT
    H = np.eye(2, 4)
    Q, R = np.diag([1e-3, 2e-3, 1e-2, 3e-2]), np.array([[0.25, 0.05], [0.05, 0.09]])
    P0 = np.diag([1.0, 2.0, 3.0, 4.0]) + 0.1
    steps, batch = 700, 2  # more than one chunk of Jacobians (CHUNK_STEPS)
    mask = rng.random((batch, steps)) < 0.5
    mask[0, :20] = False
    recorded = np.empty((batch, steps, 4, 4))

    def transitions(a: int, b: int):
        return np.broadcast_to(A, (batch, b - a, 4, 4)), np.broadcast_to(Q, (batch, b - a, 4, 4))

    def record(a: int, posterior: np.ndarray) -> None:
        recorded[:, a : a + posterior.shape[1]] = posterior

    covariance_recursion(transitions, P0, mask, np.broadcast_to(R, (steps, 2, 2)), observed=2, record=record)
    for b in range(batch):
        _, expected = linear_kalman_filter(A, H, Q, R, np.zeros(4), P0, np.zeros((steps, 2)), mask[b])
        np.testing.assert_allclose(recorded[b], expected, rtol=1e-10, atol=1e-14)


SPIN = get_scenario("spin").replace(n_steps=400)
SEEDS = 4


def test_bound_of_a_prior_family_responds_to_noise_schedule_and_inertia() -> None:
    base = posterior_bound(SPIN, SEEDS)
    assert base.state_rmse.shape == (SEEDS,) and base.component_rmse.shape == (SEEDS, 13)
    assert np.all(np.isfinite(base.state_rmse)) and np.all(base.state_rmse > 0)
    noisier = posterior_bound(SPIN.replace(noise_scale=5.0), SEEDS)
    sparser = posterior_bound(SPIN.replace(measurement_every=20), SEEDS)
    for group in ("attitude", "position", "omega", "velocity"):
        assert np.all(noisier.group_rmse[group] > base.group_rmse[group])
        assert np.all(sparser.group_rmse[group] > base.group_rmse[group])
    # the 13-state bound is the root of the mean of the 13 component bounds
    np.testing.assert_allclose(base.state_rmse, np.sqrt(np.mean(base.component_rmse**2, axis=1)), rtol=1e-12)
    # the quaternion components carry a quarter of the attitude error's variance (dq = Theta dtheta / 2)
    q_part = np.sum(base.component_rmse[:, :4] ** 2, axis=1)
    assert np.all(q_part < 0.25 * np.radians(base.group_rmse["attitude"]) ** 2 * 1.0001)
    summary = base.summary()
    assert summary["state"].episodes == SEEDS and summary["state"].standard_error > 0
    json.dumps(base.to_dict())  # (JSON-compatible)


def test_unknown_inertia_ratios_raise_the_free_tumble_bound() -> None:
    tumble = get_scenario("free-tumble").replace(n_steps=400)
    known = posterior_bound(tumble, 3, inertia="known")
    estimated = posterior_bound(tumble, 3)
    assert (known.inertia, estimated.inertia) == ("known", "estimated")
    assert np.all(estimated.group_rmse["omega"] >= known.group_rmse["omega"])
    assert np.all(estimated.group_rmse["attitude"] >= known.group_rmse["attitude"])


def test_a_fixed_truth_has_a_zero_bound_where_its_prior_is_a_point() -> None:
    """ds1 states one rate, position and velocity for every episode: nothing is left to estimate
    in them, so their bound is zero; the attitude is measured."""
    ds1 = get_scenario("ds1").replace(n_steps=1500)
    bound = posterior_bound(ds1, 2)
    assert bound.times[0] == pytest.approx(1350 * ds1.dt)  # the test split starts after train and val
    for group in ("position", "omega", "velocity"):
        assert np.all(bound.group_rmse[group] == 0.0)
    assert np.all(bound.group_rmse["attitude"] > 0)


def test_torque_bursts_add_process_noise_to_the_rate() -> None:
    calm = get_scenario("ds1-noise-step").replace(n_steps=1500, noise_step_scale=1.0)
    kicked = posterior_bound(calm, 2)
    still = posterior_bound(calm.replace(kick_rate=0.0), 2)
    assert np.all(still.group_rmse["omega"] == 0.0)
    assert np.all(kicked.group_rmse["omega"] > 0)


def test_bad_settings_and_efficiency() -> None:
    with pytest.raises(ValueError, match="cut must be in"):
        posterior_bound(SPIN, 1, cut=400)
    with pytest.raises(ValueError, match="inertia must be"):
        posterior_bound(SPIN, 1, inertia="guessed")
    assert efficiency(0.5, 1.0) == 0.5
    assert math.isnan(efficiency(0.5, 0.0)) and math.isnan(efficiency(math.nan, 1.0))
    assert math.isnan(efficiency(0.0, 1.0))  # a quantity the prior fixes: no ratio
