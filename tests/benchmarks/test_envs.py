"""Environment step (single and vector) and simulator episode generation."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import fkn_bench  # noqa: F401  (registers AstrobeeTumble-v0)
from fkn_bench.envs import generate_episodes


STEPS = 3000
"""Steps per round of the single environment: several of its 512-step chunks, so that the data
generation is timed with the steps, as it is for the vector environment (a round of fewer steps
than a chunk would time the steps alone: reset generates the first chunk, outside the timing)."""
ESTIMATE = np.array([1.0] + [0.0] * 12)


def test_single_env_step(benchmark: Any) -> None:
    env = gym.make("AstrobeeTumble-v0", scenario="ds1")

    def run() -> None:
        for _ in range(STEPS):
            env.step(ESTIMATE)

    def setup() -> None:  # returns nothing: pedantic() would pass a returned value as arguments
        env.reset(seed=0)

    benchmark.pedantic(run, setup=setup, rounds=5, warmup_rounds=1)
    benchmark.extra_info.update(steps=STEPS, what="AstrobeeTumble-v0 step(), 1 env")


@pytest.mark.parametrize("num_envs", [64, 1024])
def test_vector_env_step(benchmark: Any, num_envs: int) -> None:
    envs = gym.make_vec("AstrobeeTumble-v0", num_envs=num_envs, vectorization_mode="vector_entry_point")
    estimates = np.tile(ESTIMATE, (num_envs, 1))
    steps = 1000  # several chunks at either size (chunk_size=None: 512 steps at 64, 256 at 1024 envs)

    def run() -> None:
        for _ in range(steps):
            envs.step(estimates)

    def setup() -> None:
        envs.reset(seed=0)

    benchmark.pedantic(run, setup=setup, rounds=5, warmup_rounds=1)
    benchmark.extra_info.update(steps=steps * num_envs, what=f"vector step(), {num_envs} envs (env-steps)")


@pytest.mark.parametrize(("scenario", "seeds"), [("ds1", 4), ("tumble-slow", 1)])
def test_generate_episodes(benchmark: Any, scenario: str, seeds: int) -> None:
    """Whole 16000-step episodes (forced rotation; free tumbling integrates Euler's equations)."""
    episodes = benchmark.pedantic(lambda: generate_episodes(scenario, seeds), rounds=3, warmup_rounds=1)
    benchmark.extra_info.update(steps=episodes.batch_size * episodes.n_steps, what=f"generate_episodes {scenario}, {seeds} seeds")
