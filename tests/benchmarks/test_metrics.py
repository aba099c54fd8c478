"""The metrics (:func:`fkn_bench.metrics.score_run`) on a 16000-step run with covariances and
innovations (ds1, the whole episode, manual-ekf's estimates)."""

from __future__ import annotations

from typing import Any

from fkn_bench.envs import generate_episodes
from fkn_bench.estimators import make_estimator
from fkn_bench.metrics import score_run



def test_score_16000_step_run(benchmark: Any) -> None:
    episodes = generate_episodes("ds1", [0])
    estimates = make_estimator("manual-ekf").estimate(episodes.measurements, episodes.valid, episodes.scenario.dt)

    def run() -> Any:
        return score_run(
            episodes.truth,
            estimates.means,
            episodes.scenario.dt,
            error_covariances=estimates.error_covariances,
            innovations=estimates.innovations,
            innovation_covariances=estimates.innovation_covariances,
            innovation_mask=estimates.innovation_mask,
        )

    benchmark.pedantic(run, rounds=5, warmup_rounds=1)
    benchmark.extra_info.update(steps=episodes.batch_size * episodes.n_steps, what="score_run, 1 x 16000 steps")
