"""The vector environment reproduces single environments exactly, through autoresets."""

from __future__ import annotations

import re

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import fkn_bench  # noqa: F401  (registers the environment)
from fkn_bench.envs.astrobee_tumble_vector import AstrobeeTumbleVectorEnv
from fkn_bench.geometry import quaternion as quat

ENV_ID = "AstrobeeTumble-v0"


# exact comparisons of these bits: the vector and the single environments do the same element-wise
# arithmetic on the same seeded draws, and their rewards share the batched/scalar cost that
# tests/envs/test_rewards.py checks bit for bit
def _bits(x) -> bytes:
    return np.ascontiguousarray(np.asarray(x, dtype=np.float64)).tobytes()


def _compare_with_single_envs(
    vector: gym.vector.VectorEnv, singles: list[gym.Env], reset_seed, single_seeds: list[int], n_vector_steps: int
) -> dict[str, int]:
    """Step ``vector`` and ``singles`` side by side with the same estimates and assert that
    every output is bit-identical. Returns counts of what was seen."""
    n = len(singles)
    rng = np.random.default_rng(123)
    obs_v, info_v = vector.reset(seed=reset_seed)
    results = [env.reset(seed=s) for env, s in zip(singles, single_seeds)]
    needs_reset = [False] * n
    seen = {"truncations": 0, "autoresets": 0, "missing": 0, "present": 0}

    def check(obs_v, info_v, i, obs_s, info_s) -> None:
        assert _bits(obs_v["pose"][i]) == _bits(obs_s["pose"])
        assert obs_v["valid"][i] == obs_s["valid"]
        assert _bits(obs_v["time"][i]) == _bits(obs_s["time"])
        assert _bits(info_v["truth"][i]) == _bits(info_s["truth"])
        assert info_v["step"][i] == info_s["step"] and info_v["episode_seed"][i] == info_s["episode_seed"]
        seen["missing" if np.isnan(obs_s["pose"]).all() else "present"] += 1

    for i, (obs_s, info_s) in enumerate(results):
        check(obs_v, info_v, i, obs_s, info_s)
    for _ in range(n_vector_steps):
        actions = info_v["truth"] + 0.02 * rng.standard_normal((n, 13))
        obs_v, reward_v, terminated_v, truncated_v, info_v = vector.step(actions)
        assert vector.observation_space.contains(obs_v)
        for i, env in enumerate(singles):
            if needs_reset[i]:
                obs_s, info_s = env.reset()
                reward_s, terminated_s, truncated_s = 0.0, False, False
                seen["autoresets"] += 1
            else:
                obs_s, reward_s, terminated_s, truncated_s, info_s = env.step(actions[i])
            needs_reset[i] = truncated_s
            seen["truncations"] += truncated_s
            check(obs_v, info_v, i, obs_s, info_s)
            assert _bits(reward_v[i]) == _bits(reward_s)
            assert terminated_v[i] == terminated_s and truncated_v[i] == truncated_s
    return seen


def test_make_vec_gives_the_vector_class() -> None:
    vector = gym.make_vec(ENV_ID, num_envs=4)
    assert isinstance(vector, AstrobeeTumbleVectorEnv)
    assert vector.num_envs == 4
    assert vector.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert vector.single_action_space.shape == (13,) and vector.action_space.shape == (4, 13)
    assert vector.observation_space["pose"].shape == (4, 7)
    vector = gym.make_vec(ENV_ID, num_envs=2, scenario="ds2", noise_scale=5.0, measurement_every=10, dropout=0.2)
    sc = vector.scenario
    assert (sc.omega0, sc.noise_scale, sc.measurement_every, sc.dropout) == ((0.1, 0.2, 0.3), 5.0, 10, 0.2)


@pytest.mark.parametrize(
    ("scenario", "overrides"),
    [("ds1-flips", {"dropout": 0.3}), ("tumble-fast", {"measurement_every": 3}),
     ("ds1-noise-step", {"kick_rate": 0.05})],
    ids=["ds1-flips", "tumble-fast", "ds1-noise-step"],
)
def test_vector_equals_single_envs_through_autoreset(scenario: str, overrides: dict) -> None:
    n_envs, n_steps = 3, 50
    kwargs = {"scenario": scenario, "n_steps": n_steps, "expose_truth": True, **overrides}
    vector = gym.make_vec(ENV_ID, num_envs=n_envs, chunk_size=16, **kwargs)
    singles = [gym.make(ENV_ID, chunk_size=7, **kwargs) for _ in range(n_envs)]
    # two full episodes, the autoreset step between them, and into a third episode
    seen = _compare_with_single_envs(vector, singles, 10, [10, 11, 12], 2 * n_steps + 5)
    assert seen["truncations"] == 2 * n_envs and seen["autoresets"] == 2 * n_envs
    assert seen["missing"] > 0 and seen["present"] > 0
    seeds = [env.unwrapped.episode_seed for env in singles]
    assert len(set(seeds)) == n_envs and not set(seeds) & {10, 11, 12}


def test_sync_vectorization_equals_the_vector_entry_point() -> None:
    """``gym.make_vec(..., vectorization_mode="sync")`` (Gymnasium's SyncVectorEnv of single
    environments) and the batched ``vector_entry_point`` give the same bits: observations,
    rewards, flags and infos (with their masks), through Gymnasium's next-step autoreset."""
    n_steps = 20
    kwargs = {"scenario": "ds1-flips", "n_steps": n_steps, "expose_truth": True, "measurement_every": 2}
    sync = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="sync", **kwargs)
    batched = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="vector_entry_point", chunk_size=7, **kwargs)
    assert sync.metadata["autoreset_mode"] == batched.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP

    def same(out_s: tuple, out_b: tuple, step: int) -> None:
        *arrays_s, info_s = out_s
        *arrays_b, info_b = out_b
        for key in ("pose", "valid", "time"):
            assert _bits(arrays_s[0][key]) == _bits(arrays_b[0][key]), (step, key)
        for a, b in zip(arrays_s[1:], arrays_b[1:]):  # reward, terminated, truncated
            assert _bits(a) == _bits(b), step
        assert sorted(info_s) == sorted(info_b), step
        for key in info_s:
            assert _bits(info_s[key]) == _bits(info_b[key]), (step, key)

    rng = np.random.default_rng(5)
    out_s, out_b = sync.reset(seed=4), batched.reset(seed=4)
    same(out_s, out_b, -1)
    truncations = 0
    for step in range(2 * n_steps + 3):  # two episodes, the autoreset steps, into a third
        actions = out_b[-1]["truth"] + 0.05 * rng.standard_normal((3, 13))
        out_s, out_b = sync.step(actions), batched.step(actions)
        same(out_s, out_b, step)
        truncations += int(out_b[3].sum())
    assert truncations == 2 * 3


def test_reset_with_list_of_seeds() -> None:
    kwargs = {"n_steps": 30, "expose_truth": True, "measurement_every": 2}
    vector = gym.make_vec(ENV_ID, num_envs=3, **kwargs)
    singles = [gym.make(ENV_ID, **kwargs) for _ in range(3)]
    seen = _compare_with_single_envs(vector, singles, [5, 9, 2], [5, 9, 2], 35)
    assert seen["autoresets"] == 3
    obs, info = vector.reset(seed=[7, 7, 0])
    np.testing.assert_array_equal(info["episode_seed"], [7, 7, 0])
    assert _bits(obs["pose"][0]) == _bits(obs["pose"][1]) != _bits(obs["pose"][2])


def test_truncation_and_autoreset_outputs() -> None:
    vector = gym.make_vec(ENV_ID, num_envs=2, n_steps=20)
    vector.reset(seed=0)
    action = np.tile(np.concatenate([quat.IDENTITY, np.zeros(9)]), (2, 1))
    for k in range(1, 20):
        obs, reward, terminated, truncated, info = vector.step(action)
        assert truncated.tolist() == [k == 19] * 2 and not terminated.any()
        assert np.all(reward < 0)
        np.testing.assert_array_equal(info["step"], [k, k])
    obs, reward, terminated, truncated, info = vector.step(np.full((2, 13), np.nan))  # ignored
    np.testing.assert_array_equal(reward, 0.0)
    assert not truncated.any() and not terminated.any()
    np.testing.assert_array_equal(info["step"], [0, 0])
    np.testing.assert_array_equal(obs["time"], 0.0)
    assert not set(info["episode_seed"].tolist()) & {0, 1}


def test_seeded_vector_is_deterministic() -> None:
    action = np.tile(np.concatenate([quat.IDENTITY, np.zeros(9)]), (2, 1))

    def rollout(env) -> list[tuple[bytes, bytes, list[int]]]:
        env.reset(seed=4)
        out = []
        for _ in range(45):  # through two autoresets
            obs, reward, _, _, info = env.step(action)
            out.append((_bits(obs["pose"]), _bits(reward), info["episode_seed"].tolist()))
        return out

    a = gym.make_vec(ENV_ID, num_envs=2, n_steps=20)
    first = rollout(a)
    assert rollout(gym.make_vec(ENV_ID, num_envs=2, n_steps=20)) == first
    assert rollout(a) == first  # a second seeded reset of the same env starts over
    assert len({seeds[0] for _, _, seeds in first}) == 3  # seed 4 and two autoreset episodes


@pytest.mark.parametrize(
    ("actions", "pattern"),
    [
        (np.zeros((3, 12)), r"shape \(3, 13\) \(got \(3, 12\)\)"),
        (np.zeros(13), r"shape \(3, 13\) \(got \(13,\)\)"),
        (np.zeros((4, 13)), r"shape \(3, 13\) \(got \(4, 13\)\)"),
        (np.where(np.arange(13) == 0, np.nan, 1.0) * np.ones((3, 1)), r"finite: action\[0, 0\] \(qw\) is nan"),
        (np.zeros((3, 13)), "zero norm"),
    ],
)
def test_bad_actions(actions: np.ndarray, pattern: str) -> None:
    vector = gym.make_vec(ENV_ID, num_envs=3, n_steps=20)
    vector.reset(seed=0)
    with pytest.raises(ValueError, match=pattern):
        vector.step(actions)


def test_usage_errors() -> None:
    vector = AstrobeeTumbleVectorEnv(num_envs=2, n_steps=20)
    with pytest.raises(gym.error.ResetNeeded):
        vector.step(np.zeros((2, 13)))
    with pytest.raises(ValueError, match="expected 2 seeds"):
        vector.reset(seed=[1, 2, 3])
    with pytest.raises(ValueError, match="non-negative"):
        vector.reset(seed=[1, -2])
    with pytest.raises(NotImplementedError, match="together"):
        vector.reset(seed=0, options={"reset_mask": np.array([True, False])})
    for bad in (0, -1, 2.0):
        with pytest.raises(ValueError, match="num_envs"):
            AstrobeeTumbleVectorEnv(num_envs=bad)
    with pytest.raises(ValueError, match="'dropout'"):
        gym.make_vec(ENV_ID, num_envs=2, dropout=-0.5)


def test_seeds_follow_the_single_environments_rule() -> None:
    """Issue 34, finding 7: ``reset(seed=2**70)`` was a raw OverflowError here while the single
    environment accepted it; both now refuse seeds of 2**63 or more (stored as int64) with the
    same message, and take numpy integers alike."""
    vector = AstrobeeTumbleVectorEnv(num_envs=2, n_steps=20)
    single = gym.make(ENV_ID, n_steps=20)
    for seed in (2**70, 2**63):
        with pytest.raises(ValueError, match=r"^seed must be below 2\*\*63, seeds are stored as int64") as caught:
            vector.reset(seed=seed)
        with pytest.raises(ValueError, match=re.escape(str(caught.value))):
            single.reset(seed=seed)
    with pytest.raises(ValueError, match=r"^seed \+ 1 \(the seed of sub-environment 1\) must be below 2\*\*63"):
        vector.reset(seed=2**63 - 1)
    with pytest.raises(ValueError, match=r"^seed\[1\] must be a non-negative integer \(got 1.0\)"):
        vector.reset(seed=[0, 1.0])
    _, info = vector.reset(seed=np.array([2**63 - 1, 5], dtype=np.uint64))
    np.testing.assert_array_equal(info["episode_seed"], [2**63 - 1, 5])
    assert single.reset(seed=np.int64(5))[1]["episode_seed"] == 5


def test_actions_beyond_action_limit_are_refused() -> None:
    """1e308 gave the reward -inf (issue 34, finding 7), as in the single environment."""
    vector = AstrobeeTumbleVectorEnv(num_envs=2, n_steps=20)
    vector.reset(seed=0)
    actions = np.tile(np.eye(1, 13)[0], (2, 1))
    actions[1, 5] = -1e308
    with pytest.raises(ValueError, match=r"^action must be within \+-ACTION_LIMIT = 1e\+150: action\[1, 5\] \(ry\) is -1e\+308"):
        vector.step(actions)
