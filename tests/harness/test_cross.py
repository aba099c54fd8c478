"""The cross-scenario scores: a family's committed parameters scored on other scenarios."""

from __future__ import annotations

import copy

import numpy as np

from fkn_bench.envs import generate_episodes
from fkn_bench.estimators import make_estimator
from fkn_bench.harness.cross import cross_scores
from fkn_bench.metrics import score_run
from fkn_bench.scenarios import get_scenario
from fkn_bench.training.artifacts import artifact_path


def test_cross_scores_equal_a_direct_run_and_skip_missing_artefacts() -> None:
    scores = cross_scores(["direct-tuned-ekf"], ["ds1", "no-such-family"], ["ds2"], 2)
    assert list(scores) == [("direct-tuned-ekf", "ds1", "ds2")]
    scenario = get_scenario("ds2")
    episodes = generate_episodes(scenario, [0, 1], split="test")
    estimator = make_estimator("direct-tuned-ekf", parameters=artifact_path("direct-tuned-ekf", "ds1"))
    estimates = copy.deepcopy(estimator).estimate(episodes.measurements, episodes.valid, scenario.dt)
    expected = score_run(episodes.truth, estimates.means, scenario.dt, error_covariances=estimates.error_covariances)
    rmse, diverged = scores["direct-tuned-ekf", "ds1", "ds2"]
    assert rmse == np.mean(expected.state_rmse) and diverged == np.mean(expected.divergence.diverged)
