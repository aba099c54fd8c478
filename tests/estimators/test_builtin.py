"""The built-in estimators: the paper's manual tuning on each variant, and the oracle EKF."""

from __future__ import annotations

import numpy as np
import pytest

from fkn_bench.estimators import KalmanEstimator, make_estimator
from fkn_bench.estimators.builtin import manual_estimator, oracle_ekf
from fkn_bench.estimators.oracle import oracle_noise
from fkn_bench.scenarios import get_scenario

PAPER_Q = [0.005] * 4 + [1e-4] * 3 + [0.005] * 3 + [1e-4] * 3  # FlexKalmanNet section 4.3
PAPER_R = [0.1] * 7


def test_manual_ekf_and_ukf_use_the_papers_tuning() -> None:
    for variant in ("ekf", "ukf"):
        estimator = make_estimator(f"manual-{variant}")
        assert isinstance(estimator, KalmanEstimator) and estimator.variant_name == variant
        assert estimator.name == f"manual-{variant}" and variant.upper() in estimator.description
        config = estimator.to_config()
        assert config["q_std"] == PAPER_Q and config["r_std"] == PAPER_R
        assert config["p0_std"] == [0.1] * 7 + [0.2] * 3 + [0.003] * 3


def test_manual_mekf_maps_the_tuning_to_the_error_state() -> None:
    config = make_estimator("manual-mekf").to_config()
    assert config["variant"] == "mekf"
    # quaternion-component std s -> attitude std 2 s (rad)
    assert config["r_std"] == [0.2] * 3 + [0.1] * 3
    assert config["q_std"] == [0.01] * 3 + [1e-4] * 3 + [0.005] * 3 + [1e-4] * 3
    assert config["p0_std"] == [0.2] * 3 + [0.1] * 3 + [0.2] * 3 + [0.003] * 3


def test_factories_take_a_scenario_and_options() -> None:
    scenario = get_scenario("ds2")
    estimator = make_estimator("manual-ekf", scenario=scenario, name="mine", r_std=[0.2] * 7)
    assert estimator.name == "mine" and estimator.to_config()["r_std"] == [0.2] * 7
    assert manual_estimator("mekf")().variant_name == "mekf"  # type: ignore[attr-defined]
    with pytest.raises(ValueError, match="unknown filter variant"):
        manual_estimator("pf")()


def test_oracle_ekf_uses_the_scenarios_true_noise() -> None:
    scenario = get_scenario("ds1-noise5x")
    estimator = make_estimator("oracle-ekf", scenario=scenario)
    q_std, r_std = oracle_noise(scenario)
    config = estimator.to_config()
    assert config["variant"] == "ekf" and estimator.name == "oracle-ekf"
    # exact: oracle_noise is the same computation twice; to_config's sqrt(diag(std**2)) gives std back
    # bit for bit (sqrt(fl(x*x)) == |x| in binary64 with correctly rounded * and sqrt)
    np.testing.assert_array_equal(config["q_std"], q_std)
    np.testing.assert_array_equal(config["r_std"], r_std)
    assert "ds1-noise5x" in estimator.description
    with pytest.raises(ValueError, match="oracle-ekf needs the scenario whose true noise it uses"):
        make_estimator("oracle-ekf")
    with pytest.raises(ValueError, match="needs the scenario"):
        oracle_ekf()


def test_rigid_body_estimators() -> None:
    """Known inertia from the scenario (Astrobee's without one); ratios estimated from an
    isotropic prior; a 13-state report with the ratios in the extras; online == batch."""
    from fkn_bench.envs import generate_episodes
    from fkn_bench.scenarios import ASTROBEE_INERTIA

    scenario = get_scenario("tumble-fast").replace(inertia=(0.2, 0.15, 0.25))
    known = make_estimator("rigid-body-ekf", scenario=scenario)
    assert known.to_config()["inertia"] == [0.2, 0.15, 0.25] and known.to_config()["model"] == "rigid-body"
    assert make_estimator("rigid-body-ukf").to_config()["inertia"] == list(ASTROBEE_INERTIA)
    ratios = make_estimator("rigid-body-ekf-ratios", scenario=scenario)
    assert ratios.to_config()["inertia"] is None and len(ratios.q_std) == 15
    episodes = generate_episodes("tumble-fast", 2, split="test").window(0, 300)
    batch = ratios.estimate(episodes.measurements, episodes.valid, 0.1)
    assert batch.means.shape == (2, 300, 13) and batch.covariances.shape == (2, 300, 13, 13)
    assert batch.extras["inertia_ratios"].shape == (2, 300, 2)
    ratios.reset(dt=0.1)
    for t in range(300):
        estimate = ratios.step(episodes.measurements[1, t])
    np.testing.assert_allclose(estimate.mean, batch.means[1, -1], rtol=0, atol=1e-10)
    np.testing.assert_allclose(estimate.native_covariance, batch.covariances[1, -1], rtol=0, atol=1e-12)
    rebuilt = KalmanEstimator.from_config(ratios.to_config())
    np.testing.assert_array_equal(rebuilt.estimate(episodes.measurements, episodes.valid, 0.1).means, batch.means)
    with pytest.raises(ValueError, match="unknown process model"):
        KalmanEstimator(model="spinning-top")
    mekf = KalmanEstimator(variant="mekf", model="rigid-body-ratios")
    estimates = mekf.estimate(episodes.measurements, episodes.valid, 0.1)
    assert estimates.error_covariances.shape == (2, 300, 12, 12) and estimates.extras["inertia_ratios"].shape == (2, 300, 2)
    with pytest.raises(ValueError, match="q_std needs 15 values"):
        KalmanEstimator(model="rigid-body-ratios", q_std=[0.01] * 13)
