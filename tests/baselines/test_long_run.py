"""Long-run stability: 1e5 steps of ds1-flips (random quaternion sign flips, 1% gross outliers)
through every baseline, batched estimate(): no NaN, and every 12x12 error covariance positive
definite."""

from __future__ import annotations

import numpy as np
import pytest

from fkn_bench.envs import generate_episodes
from fkn_bench.estimators import make_estimator
from fkn_bench.scenarios import get_scenario

BASELINES = ("sage-husa", "akhlaghi", "vbakf", "nll-tuned-ekf", "direct-tuned-ekf")
STEPS = 100_000


@pytest.fixture(scope="module")
def long_flips():  # noqa: ANN201
    scenario = get_scenario("ds1-flips", n_steps=STEPS)
    return scenario, generate_episodes(scenario, [7])


@pytest.mark.slow
@pytest.mark.parametrize("name", BASELINES)
def test_no_nan_and_positive_definite_covariances_over_1e5_steps(name: str, long_flips) -> None:
    scenario, episodes = long_flips
    assert episodes.n_steps == STEPS and (episodes.measurements[episodes.valid][:, 0] < 0).any()
    result = make_estimator(name, scenario=scenario).estimate(episodes.measurements, episodes.valid, scenario.dt)
    for array in (result.means, result.covariances, result.innovations, result.innovation_covariances):
        assert np.isfinite(array).all()
    error_covariances = result.error_covariances[0]
    assert np.isfinite(error_covariances).all()
    for start in range(0, STEPS, 20_000):  # in chunks: eigvalsh of 1e5 12x12 matrices at once is large
        assert np.linalg.eigvalsh(error_covariances[start : start + 20_000]).min() > 0
    # the estimate keeps tracking over the last 1000 steps, except Akhlaghi's (documented in
    # fkn_bench.baselines.akhlaghi: outliers inflate its residual-based R, and the sluggish
    # filter's own error then keeps R inflated: it drifts for long stretches, metres and tens of
    # degrees off, though finite and positive definite)
    final = slice(STEPS - 1000, STEPS)
    position_error = np.linalg.norm(result.means[0, final, 4:7] - episodes.truth[0, final, 4:7], axis=-1)
    if name != "akhlaghi":
        assert np.sqrt((position_error**2).mean()) < 0.2
