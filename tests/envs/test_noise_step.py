"""The non-stationary scenario of issue 21 (``DS1_NOISE_STEP``): a measurement-noise step in the
middle third of each split and bursts of unmodelled torque."""

from __future__ import annotations

import numpy as np
import pytest

from fkn_bench.envs.dynamics import ForcedRotation, PerturbedRotation
from fkn_bench.envs.episodes import generate_episodes, rate_offsets
from fkn_bench.geometry import quaternion as quat
from fkn_bench.scenarios import DS1_NOISE_STEP, ConfigError, get_scenario


def test_noise_factor_is_five_in_the_middle_third_of_each_split() -> None:
    factor = DS1_NOISE_STEP.noise_factor(np.arange(16000))
    # train [0, 12800), val [12800, 14400), test [14400, 16000): middle thirds by integer division
    changes = np.flatnonzero(np.diff(factor)) + 1
    np.testing.assert_array_equal(changes, [4266, 8533, 13333, 13866, 14933, 15466])
    assert set(factor[changes[::2]]) == {5.0} and set(factor[changes[1::2]]) == {1.0} and factor[0] == 1.0
    assert (get_scenario("ds1").noise_factor(np.arange(16000)) == 1.0).all()


def test_measurements_carry_the_step_on_ds1_noise_draws() -> None:
    """Common random numbers: with the bursts off, the position errors equal ds1's outside the
    step and are 5x them inside (same draws); the attitude error angle likewise."""
    calm = generate_episodes("ds1", 3, split="test")
    step = generate_episodes(DS1_NOISE_STEP.replace(kick_rate=0.0), 3, split="test")
    np.testing.assert_array_equal(step.truth, calm.truth)
    factor = DS1_NOISE_STEP.noise_factor(np.arange(14400, 16000))
    valid = calm.valid
    error_calm = (calm.measurements[..., 4:7] - calm.truth[..., 4:7])[valid]
    error_step = (step.measurements[..., 4:7] - step.truth[..., 4:7])[valid]
    scale = np.broadcast_to(factor, valid.shape)[valid][:, None]
    np.testing.assert_allclose(error_step, scale * error_calm, rtol=1e-9, atol=1e-12)
    angle = [np.linalg.norm(quat.to_rotation_vector(quat.multiply(e.measurements[..., :4][valid],
                                                                   quat.conjugate(e.truth[..., :4][valid]))), axis=-1)
             for e in (calm, step)]
    np.testing.assert_allclose(angle[1], scale[:, 0] * angle[0], rtol=1e-6, atol=1e-9)
    inside = scale[:, 0] == 5.0
    assert 0.4 < error_step[inside].std() < 0.6 and 0.08 < error_step[~inside].std() < 0.12


def test_torque_bursts_perturb_the_rate_and_the_attitude_follows_it() -> None:
    """The offsets are zero before the first burst, bursts start at about ``kick_rate`` per step,
    the truth's rate is ``omega0 + d`` and its attitude ``q_{k+1} = exp(omega_k dt / 2) q_k``;
    with zero offsets :class:`PerturbedRotation` is :class:`ForcedRotation`."""
    sc = DS1_NOISE_STEP
    d = rate_offsets(sc, [0, 1])
    moving = np.abs(d).sum(-1) > 0
    assert 0.5 < np.abs(d).max() / (sc.kick_sigma * np.sqrt(sc.kick_length)) < 10
    starts = (moving[:, 1:] & ~moving[:, :-1]).sum(1)  # offsets never return to exactly 0 after one
    assert (starts == 1).all() and (~moving[:, 0]).all()
    episode = generate_episodes(sc, [0, 1], split="full")
    np.testing.assert_allclose(episode.truth[..., 7:10], np.array(sc.omega0) + d, rtol=0, atol=1e-15)
    q, omega = episode.truth[..., :4], episode.truth[..., 7:10]
    stepped = quat.multiply(quat.from_rotation_vector(omega[:, :-1] * sc.dt), q[:, :-1])
    np.testing.assert_allclose(stepped, q[:, 1:], rtol=0, atol=1e-11)
    q0 = q[:, 0]
    forced = ForcedRotation(q0, np.tile(sc.omega0, (2, 1)), sc.dt).sample(0, 16000)
    perturbed = PerturbedRotation(q0, np.tile(sc.omega0, (2, 1)), np.zeros((2, 16000, 3)), sc.dt).sample(0, 16000)
    np.testing.assert_allclose(perturbed[0], forced[0], rtol=0, atol=1e-11)


def test_torque_bursts_need_forced_dynamics_and_leave_other_hashes_alone() -> None:
    with pytest.raises(ConfigError, match="dynamics"):
        get_scenario("tumble-fast").replace(kick_rate=0.01, kick_length=5, kick_sigma=0.01)
    assert get_scenario("ds1").config_hash() == "54c803d2a4670c32"  # as before the new fields
    assert get_scenario("ds1-noise-step") == DS1_NOISE_STEP and DS1_NOISE_STEP.model_family == "ds1-noise-step"
