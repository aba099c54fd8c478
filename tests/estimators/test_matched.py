"""The model-matched references (fkn_bench.estimators.matched): what the factory matches and what
it refuses, and, on a short spin episode, a consistent oracle that the smoother beats."""

from __future__ import annotations

import numpy as np
import pytest

from fkn_bench.envs import generate_episodes
from fkn_bench.estimators import Estimator, load_estimator, make_estimator
from fkn_bench.estimators.matched import GATE, PRIOR_FLOOR_STD, PROCESS_STD, NonCausalError
from fkn_bench.metrics.errors import error_state
from fkn_bench.scenarios import get_scenario
from fkn_bench.scenarios.prior import error_prior


@pytest.mark.parametrize(("scenario", "reason"), [("ds1", "prior rate mean"), ("ds1-noise-step", "torque bursts")])
@pytest.mark.parametrize("name", ["oracle-matched", "smoother-matched"])
def test_the_factory_refuses_what_it_cannot_match_by_name(name: str, scenario: str, reason: str) -> None:
    with pytest.raises(ValueError, match=reason):
        make_estimator(name, scenario=get_scenario(scenario))
    with pytest.raises(ValueError, match="needs the scenario"):
        make_estimator(name)


def test_spin_gets_the_constant_rate_model_and_the_truths_noise_and_prior() -> None:
    scenario = get_scenario("spin")
    estimator = make_estimator("oracle-matched", scenario=scenario)
    Q, R, P0 = estimator._numpy_noise
    assert (estimator.variant_name, estimator.model_name, estimator.filter.gate) == ("mekf", "constant-velocity", None)
    sa, sp = scenario.sigma_attitude_effective, scenario.sigma_position_effective
    np.testing.assert_array_equal(R, np.diag([sa**2] * 3 + [sp**2] * 3))
    np.testing.assert_array_equal(Q, PROCESS_STD**2 * np.eye(12))
    expected = error_prior(scenario).covariance.copy()
    expected[0:6, 0:6] = np.diag([sa**2] * 3 + [sp**2] * 3)
    np.testing.assert_array_equal(P0, expected)
    assert make_estimator("oracle-matched", scenario=get_scenario("spin-flips")).filter.gate == GATE


def test_free_tumble_estimates_the_inertia_ratios_with_the_correlated_prior() -> None:
    scenario = get_scenario("free-tumble")
    estimator = make_estimator("oracle-matched", scenario=scenario)
    assert (estimator.model_name, estimator.inertia) == ("rigid-body-ratios", scenario.inertia)
    P0 = estimator._numpy_noise[2]
    prior = error_prior(scenario).covariance
    assert P0.shape == (14, 14) and P0[12, 13] < 0
    np.testing.assert_array_equal(P0[6:, 6:], prior[6:, 6:])
    fixed = make_estimator("oracle-matched", scenario=get_scenario("tumble-flip"))  # known inertia, fixed velocity
    assert fixed.model_name == "rigid-body" and fixed._numpy_noise[2].shape == (12, 12)
    np.testing.assert_array_equal(np.diag(fixed._numpy_noise[2])[9:], PRIOR_FLOOR_STD**2)


def test_a_noise_step_scenario_gets_the_truths_noise_schedule_and_it_survives_a_round_trip(tmp_path) -> None:  # noqa: ANN001
    scenario = get_scenario("spin-noise-step")
    estimator = make_estimator("oracle-matched", scenario=scenario)
    R = estimator.noise_schedule(30).measurement.numpy()[0, :, 0, 0]
    factor = scenario.replace(n_steps=30).noise_factor(np.arange(30))  # one split = the whole episode
    np.testing.assert_allclose(R, factor**2 * scenario.sigma_attitude_effective**2, rtol=1e-15)
    np.testing.assert_array_equal(estimator.noise_schedule(10, offset=20).measurement.numpy()[0, :, 0, 0], R[20:])
    loaded = load_estimator(estimator.save(tmp_path / "matched.json"))
    assert loaded.to_config() == estimator.to_config() and loaded.noise_step_scale == 5.0


def test_the_smoother_is_labelled_non_causal_and_has_no_online_step() -> None:
    smoother = make_estimator("smoother-matched", scenario=get_scenario("spin"))
    assert smoother.causal is False and make_estimator("oracle-matched", scenario=get_scenario("spin")).causal is True
    assert smoother.description.startswith("non-causal:") and Estimator.causal is True
    for call in (lambda: smoother.reset(dt=0.1), lambda: smoother.step(np.zeros(7))):
        with pytest.raises(NonCausalError, match="non-causal"):
            call()


@pytest.fixture(scope="module")
def spin_runs() -> dict[str, object]:
    scenario = get_scenario("spin").replace(n_steps=300)
    episodes = generate_episodes(scenario, [0, 1, 2], split="test")
    runs = {name: make_estimator(name, scenario=scenario).estimate(episodes.measurements, episodes.valid, scenario.dt)
            for name in ("oracle-matched", "smoother-matched")}
    return {"truth": episodes.truth, **runs}


def _rmse(truth: np.ndarray, estimates) -> float:  # noqa: ANN001
    return float(np.sqrt(np.mean(error_state(truth, estimates.means)[:, 100:] ** 2)))


def test_on_spin_the_oracle_is_consistent_and_the_smoother_beats_it(spin_runs: dict[str, object]) -> None:
    truth, oracle, smoother = spin_runs["truth"], spin_runs["oracle-matched"], spin_runs["smoother-matched"]
    for estimates in (oracle, smoother):
        assert np.isfinite(estimates.means).all() and np.isfinite(estimates.error_covariances).all()
        assert estimates.error_covariances.shape == (3, 300, 12, 12) and estimates.covariances.shape == (3, 300, 13, 13)
    error = error_state(truth, oracle.means)[:, 100:]
    nees = np.einsum("bti,bti->bt", error, np.linalg.solve(oracle.error_covariances[:, 100:], error[..., None])[..., 0])
    assert 6.0 < nees.mean() < 24.0  # 12 degrees of freedom (3 seeds, 200 correlated steps)
    assert _rmse(truth, smoother) < 0.8 * _rmse(truth, oracle)
    np.testing.assert_array_equal(smoother.initialised, oracle.initialised)
    assert smoother.innovations is None and smoother.innovation_mask is not None
