"""The oracle's noise parameters, derived from a scenario's ground truth."""

from __future__ import annotations

import numpy as np
import torch

from fkn_bench.estimators.oracle import PROCESS_FLOOR, model_prediction, oracle_noise
from fkn_bench.models import PoseTwistModel
from fkn_bench.scenarios import get_scenario

# an error rotation of 0.1 rad per axis moves each unit-quaternion component by
# 0.1 * sqrt(3/4) / 2 on average (the projection onto the unit sphere): 0.0433
QUATERNION_STD = 0.1 * np.sqrt(3.0 / 4.0) / 2.0


def test_ds1_measurement_noise() -> None:
    q_std, r_std = oracle_noise(get_scenario("ds1"))
    assert q_std.shape == (13,) and r_std.shape == (7,)
    # 1280 training measurements: the std of a std is ~2%; individual quaternion components
    # depend on one episode's attitude distribution, their average does not
    assert abs(r_std[:4].mean() - QUATERNION_STD) < 0.03 * QUATERNION_STD
    assert (np.abs(r_std[:4] - QUATERNION_STD) < 0.25 * QUATERNION_STD).all()
    np.testing.assert_allclose(r_std[4:], 0.1, rtol=0.05)


def test_ds1_process_noise_sits_at_the_floor_for_forced_rotation() -> None:
    q_std, _ = oracle_noise(get_scenario("ds1"))
    # r, w, v follow the model exactly under forced rotation at constant rate with v = 0
    # exact: np.maximum returns the floor constant itself; the residuals are 0 or rounding-sized (<< 1e-7)
    np.testing.assert_array_equal(q_std[4:], PROCESS_FLOOR)
    # the quaternion carries the first-order discretisation error ~ (|w| dt)^2 / 8 per step
    assert (q_std[:4] > PROCESS_FLOOR).all() and (q_std[:4] < 1e-5).all()


def test_tumble_slow_rates_are_above_the_floor() -> None:
    q_std, r_std = oracle_noise(get_scenario("tumble-slow"))
    # torque-free tumbling with a non-isotropic inertia: the world-frame rate changes
    assert (q_std[7:10] > 10 * PROCESS_FLOOR).all()
    np.testing.assert_array_equal(q_std[4:7], PROCESS_FLOOR)  # exact: the floor constant (as above)
    np.testing.assert_array_equal(q_std[10:13], PROCESS_FLOOR)
    assert abs(r_std[:4].mean() - QUATERNION_STD) < 0.03 * QUATERNION_STD


def test_noise_scale_scales_the_measurement_noise() -> None:
    _, base = oracle_noise(get_scenario("ds1"))
    _, scaled = oracle_noise(get_scenario("ds1-noise5x"))
    np.testing.assert_allclose(scaled[4:], 5.0 * base[4:], rtol=1e-9)  # common random numbers
    assert abs(scaled[:4].mean() / base[:4].mean() - 5.0) < 0.5  # attitude: not exactly linear on the sphere


def test_model_prediction_is_the_filters_model() -> None:
    rng = np.random.default_rng(0)
    x = rng.standard_normal((6, 13))
    expected = PoseTwistModel().predict(torch.from_numpy(x), 0.1).numpy()
    np.testing.assert_allclose(model_prediction(x, 0.1), expected, rtol=0, atol=1e-15)
    np.testing.assert_allclose(model_prediction(x.reshape(2, 3, 13), 0.1), expected.reshape(2, 3, 13), rtol=0, atol=1e-15)


def test_a_prior_familys_oracle_pools_its_training_episodes() -> None:
    """Every episode of free-tumble has its own rate: the oracle's process noise is the RMS
    residual over PRIOR_EPISODES training episodes, not one drawn rate's."""
    from fkn_bench.envs import generate_episodes
    from fkn_bench.scenarios import PRIOR_EPISODES

    short = get_scenario("free-tumble", n_steps=60)
    q_std, _ = oracle_noise(short)
    truth = generate_episodes(short, PRIOR_EPISODES, split="train").truth
    residual = truth[:, 1:] - model_prediction(truth[:, :-1], short.dt)
    np.testing.assert_allclose(q_std[7:10], np.sqrt((residual[..., 7:10] ** 2).mean(axis=(0, 1))), rtol=1e-12)
    one = np.sqrt((residual[0, :, 7:10] ** 2).mean(axis=0))
    assert not np.allclose(q_std[7:10], one, rtol=0.1)  # the first episode alone is another rate's
