"""``AstrobeeReplay-v0``: registration, the same conventions as AstrobeeTumble-v0, seeding,
recorded versus synthesised measurements, truncation, Gymnasium's checker and input errors."""

from __future__ import annotations

import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import fkn_bench  # noqa: F401  (registers the environments)
from fkn_bench.envs.astrobee_replay import AstrobeeReplayEnv
from fkn_bench.envs.astrobee_tumble import AstrobeeTumbleEnv
from fkn_bench.envs.replay import load_episodes
from fkn_bench.exporters.recording import record
from fkn_bench.recordings import RecordingError

ENV_ID = "AstrobeeReplay-v0"
STEPS = 120


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("replay") / "run.mcap"
    record(path, scenario="ds1", estimator=None, seed=4, n_steps=STEPS)
    return path


def _run(env: gym.Env, seed: int | None) -> dict[str, list]:
    """Reset and step to the truncation with the true state as the estimate."""
    obs, info = env.reset(seed=seed)
    out = {"obs": [obs], "info": [info], "reward": [], "truncated": []}
    while True:
        obs, reward, terminated, truncated, info = env.step(out["info"][-1]["truth"])
        assert terminated is False
        for key, value in (("obs", obs), ("info", info), ("reward", reward), ("truncated", truncated)):
            out[key].append(value)
        if truncated:
            return out


def test_registered_and_made_with_a_path(recording: Path) -> None:
    assert ENV_ID in gym.registry
    env = gym.make(ENV_ID, path=recording)
    assert isinstance(env.unwrapped, AstrobeeReplayEnv)
    assert env.spec is not None and env.spec.id == ENV_ID
    assert env.unwrapped.scenario.n_steps == STEPS and env.unwrapped.scenario.dt == 0.1
    assert env.unwrapped.report.truth_topic == "/loc/truth/pose"
    env.close()
    prefixed = gym.make(f"fkn_bench:{ENV_ID}", path=str(recording))
    assert isinstance(prefixed.unwrapped, AstrobeeReplayEnv)


def test_same_spaces_as_astrobee_tumble(recording: Path) -> None:
    replay = gym.make(ENV_ID, path=recording).unwrapped
    tumble = AstrobeeTumbleEnv(n_steps=STEPS)
    assert replay.action_space == tumble.action_space
    assert replay.observation_space == tumble.observation_space
    assert replay.metadata == tumble.metadata


def test_episode_matches_load_episodes_and_true_estimates_score_zero(recording: Path) -> None:
    env = gym.make(ENV_ID, path=recording, expose_truth=True)
    run = _run(env, seed=4)
    episodes = load_episodes(recording, seed=4)
    poses = np.array([o["pose"] for o in run["obs"]])
    assert np.array_equal(poses, episodes.measurements[0], equal_nan=True)
    assert [int(o["valid"]) for o in run["obs"]] == episodes.valid[0].astype(int).tolist()
    assert [float(o["time"]) for o in run["obs"]] == episodes.times.tolist()
    assert np.array_equal(np.array([i["truth"] for i in run["info"]]), episodes.truth[0])
    assert len(run["reward"]) == STEPS - 1 and run["truncated"][-1] and not any(run["truncated"][:-1])
    assert all(r == 0.0 for r in run["reward"])
    assert run["info"][0]["episode_seed"] == 4
    with pytest.raises(gym.error.ResetNeeded):
        env.unwrapped.step(episodes.truth[0, -1])


def test_replay_equals_the_simulated_episode(recording: Path) -> None:
    """The recording was made from ds1 seed 4: replaying it with seed 4 gives the same data as
    AstrobeeTumble-v0 with that seed."""
    replay = _run(gym.make(ENV_ID, path=recording, expose_truth=True), seed=4)
    tumble = _run(gym.make("AstrobeeTumble-v0", n_steps=STEPS, expose_truth=True), seed=4)
    for a, b in zip(replay["obs"], tumble["obs"]):
        assert np.array_equal(a["pose"], b["pose"], equal_nan=True) and a["valid"] == b["valid"]
    assert replay["reward"] == tumble["reward"]


def test_recorded_measurements_do_not_depend_on_the_seed(recording: Path) -> None:
    env = gym.make(ENV_ID, path=recording, measurement_topic="/fkn_bench/measured_pose")
    first, _ = env.reset(seed=0)
    again, _ = env.reset(seed=1)
    assert np.array_equal(first["pose"], again["pose"], equal_nan=True)
    synthesised = gym.make(ENV_ID, path=recording)
    a, _ = synthesised.reset(seed=0)
    b, _ = synthesised.reset(seed=1)
    assert not np.array_equal(a["pose"], b["pose"], equal_nan=True)


def test_unseeded_reset_draws_an_episode_seed(recording: Path) -> None:
    env = gym.make(ENV_ID, path=recording)
    env.reset(seed=None)
    first = env.unwrapped.episode_seed
    env.reset()
    assert isinstance(first, int) and isinstance(env.unwrapped.episode_seed, int)
    _, info = env.reset(seed=7)
    assert info["episode_seed"] == 7 and "truth" not in info


def test_check_env_passes_with_only_the_action_space_recommendation(recording: Path) -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(gym.make(ENV_ID, path=recording).unwrapped)
    messages = [str(w.message) for w in caught if "render_mode='human' has no window" not in str(w.message)]
    assert [m for m in messages if "symmetric and normalized" not in m] == []


def test_render_and_argument_errors(recording: Path, tmp_path: Path) -> None:
    env = gym.make(ENV_ID, path=recording, render_mode="ansi")
    env.reset(seed=0)
    assert env.render().startswith("replay run.mcap seed=0 step=0 t=0.00s pose=")
    with pytest.raises(ValueError, match="render_mode"), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # gym.make warns about the unknown mode first
        gym.make(ENV_ID, path=recording, render_mode="video")
    with pytest.raises(RecordingError, match="recording not found"):
        gym.make(ENV_ID, path=tmp_path / "missing.mcap")
    fresh = gym.make(ENV_ID, path=recording).unwrapped
    with pytest.raises(gym.error.ResetNeeded):
        fresh.step(np.zeros(13))
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(12))
