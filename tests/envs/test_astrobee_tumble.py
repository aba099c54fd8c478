"""The single ``AstrobeeTumble-v0`` environment: registration, kwargs, observations, seeding,
truncation, reward, Gymnasium's checker and input errors."""

from __future__ import annotations

import math
import subprocess
import sys
import textwrap
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import fkn_bench  # noqa: F401  (registers the environment)
from fkn_bench.envs import generate_episodes
from fkn_bench.envs.astrobee_tumble import AstrobeeTumbleEnv
from fkn_bench.envs.spaces import MeasuredPose
from fkn_bench.geometry import quaternion as quat
from fkn_bench.scenarios import ConfigError, Scenario, UnknownScenarioError, get_scenario

ENV_ID = "AstrobeeTumble-v0"


def _run(env: gym.Env, seed: int, n_steps: int, actions=None) -> dict[str, list]:
    """Reset with ``seed`` and step to the truncation with the true state (or ``actions(k,
    truth)``) as the estimate; needs ``expose_truth=True``."""
    obs, info = env.reset(seed=seed)
    record = {"obs": [obs], "info": [info], "reward": [], "terminated": [], "truncated": []}
    for k in range(n_steps - 1):
        truth = info["truth"]
        action = truth if actions is None else actions(k, truth)
        obs, reward, terminated, truncated, info = env.step(action)
        outputs = {"obs": obs, "info": info, "reward": reward, "terminated": terminated, "truncated": truncated}
        for key, value in outputs.items():
            record[key].append(value)
    return record


# ---------------------------------------------------------------------------- registration
def test_make_after_import() -> None:
    assert ENV_ID in gym.registry
    env = gym.make(ENV_ID)
    assert isinstance(env.unwrapped, AstrobeeTumbleEnv)
    assert env.spec is not None and env.spec.id == ENV_ID
    assert env.unwrapped.scenario == get_scenario("ds1")
    env.close()


def test_make_with_module_prefix_in_fresh_interpreter() -> None:
    code = textwrap.dedent(
        """
        import sys
        import gymnasium as gym
        assert "fkn_bench" not in sys.modules
        env = gym.make("fkn_bench:AstrobeeTumble-v0", n_steps=50)
        obs, info = env.reset(seed=0)
        print(type(env.unwrapped).__name__, env.unwrapped.scenario.name, obs["pose"].shape)
        """
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["AstrobeeTumbleEnv", "ds1", "(7,)"]


def test_kwargs_select_scenario_and_override_fields() -> None:
    env = gym.make(ENV_ID, scenario="ds2", noise_scale=5.0, measurement_every=10, dropout=0.2)
    sc = env.unwrapped.scenario
    assert sc.omega0 == (0.1, 0.2, 0.3) and sc.model_family == "ds2"
    assert (sc.noise_scale, sc.measurement_every, sc.dropout) == (5.0, 10, 0.2)
    assert sc == get_scenario("ds2", noise_scale=5.0, measurement_every=10, dropout=0.2)
    custom = Scenario(name="mine", n_steps=30, measurement_every=2)
    assert gym.make(ENV_ID, scenario=custom).unwrapped.scenario == custom
    assert gym.make(ENV_ID, scenario="tumble-fast", n_steps=40).unwrapped.scenario.dynamics == "free"


# ---------------------------------------------------------------------------- observations and data
def test_observation_layout() -> None:
    env = gym.make(ENV_ID, n_steps=50, expose_truth=False)
    obs, info = env.reset(seed=0)
    assert set(obs) == {"pose", "valid", "time"}
    assert isinstance(obs["pose"], MeasuredPose) and obs["pose"].shape == (7,) and obs["pose"].dtype == np.float64
    assert obs["valid"] == 1 and np.isfinite(obs["pose"]).all()
    assert obs["time"].shape == () and obs["time"] == 0.0
    assert env.observation_space.contains(obs)
    assert info == {"step": 0, "episode_seed": 0}  # no truth unless asked for
    obs, *_, info = env.step(np.concatenate([quat.IDENTITY, np.zeros(9)]))
    assert obs["valid"] == 0 and np.isnan(obs["pose"]).all()  # ds1 measures every 10th step
    assert env.observation_space.contains(obs)
    assert obs["time"] == pytest.approx(0.1)
    assert "truth" not in info and info["step"] == 1


@pytest.mark.parametrize(
    ("scenario", "overrides"),
    [
        ("ds1", {"n_steps": 1200}),
        ("ds2", {"noise_scale": 5.0, "measurement_every": 10, "dropout": 0.2, "n_steps": 700}),
        ("tumble-fast", {"n_steps": 300, "measurement_every": 3}),
        ("ds1-flips", {"n_steps": 600, "measurement_every": 1}),
        ("free-tumble", {"n_steps": 200}),  # a prior family: reset(seed=s) gives test episode s's truth
        ("spin-flips", {"n_steps": 150}),
    ],
)
def test_episode_equals_generate_episodes(scenario: str, overrides: dict) -> None:
    env = gym.make(ENV_ID, scenario=scenario, expose_truth=True, **overrides)
    seed = 11
    record = _run(env, seed, overrides["n_steps"])
    episodes = generate_episodes(get_scenario(scenario, **overrides), [seed])
    if episodes.scenario.split_mode == "episodes":  # a prior family: the env plays its test episodes
        np.testing.assert_array_equal(generate_episodes(episodes.scenario, [seed], split="test").truth, episodes.truth)
    poses = np.array([o["pose"] for o in record["obs"]])
    np.testing.assert_array_equal(poses, episodes.measurements[0])
    np.testing.assert_array_equal([o["valid"] for o in record["obs"]], episodes.valid[0].astype(int))
    np.testing.assert_array_equal([o["time"] for o in record["obs"]], episodes.times)
    np.testing.assert_array_equal(np.array([i["truth"] for i in record["info"]]), episodes.truth[0])
    assert [i["step"] for i in record["info"]] == list(range(overrides["n_steps"]))
    assert all(i["episode_seed"] == seed for i in record["info"])
    # the true state as the estimate is a perfect score
    assert all(r == 0.0 for r in record["reward"])
    assert 0 < episodes.valid.sum() < overrides["n_steps"] or overrides.get("measurement_every") == 1


def test_reset_is_deterministic() -> None:
    a = gym.make(ENV_ID, n_steps=200, dropout=0.3, expose_truth=True)
    b = gym.make(ENV_ID, n_steps=200, dropout=0.3, expose_truth=True)
    rng = np.random.default_rng(0)
    offsets = 0.01 * rng.standard_normal((199, 13))
    actions = lambda k, truth: truth + offsets[k]  # noqa: E731
    first, second, again = _run(a, 3, 200, actions), _run(b, 3, 200, actions), _run(a, 3, 200, actions)
    for other in (second, again):
        assert other["reward"] == first["reward"]
        poses = np.array([o["pose"] for o in other["obs"]])
        np.testing.assert_array_equal(poses, np.array([o["pose"] for o in first["obs"]]))
    different = _run(a, 4, 200, actions)
    assert different["reward"] != first["reward"]


def test_unseeded_resets_follow_the_seed() -> None:
    a, b = AstrobeeTumbleEnv(n_steps=20), AstrobeeTumbleEnv(n_steps=20)
    seeds_a, seeds_b = [], []
    for env, seeds in ((a, seeds_a), (b, seeds_b)):
        env.reset(seed=9)
        for _ in range(3):
            env.reset()
            seeds.append(env.episode_seed)
    assert seeds_a == seeds_b and len(set(seeds_a)) == 3 and 9 not in seeds_a
    obs, _ = a.reset()
    episodes = generate_episodes(a.scenario, [a.episode_seed])
    np.testing.assert_array_equal(obs["pose"], episodes.measurements[0, 0])


def test_truncation_at_scenario_length() -> None:
    env = gym.make(ENV_ID, n_steps=50, expose_truth=True)
    record = _run(env, 0, 50)
    assert len(record["reward"]) == 49
    assert record["truncated"] == [False] * 48 + [True]
    assert not any(record["terminated"])
    assert record["info"][-1]["step"] == 49
    assert record["obs"][-1]["time"] == pytest.approx(4.9)
    with pytest.raises(gym.error.ResetNeeded):
        env.step(record["info"][-1]["truth"])
    env.reset(seed=1)  # a new episode starts fine
    env.step(np.concatenate([quat.IDENTITY, np.zeros(9)]))


def test_step_before_reset() -> None:
    with pytest.raises(gym.error.ResetNeeded):
        AstrobeeTumbleEnv(n_steps=20).step(np.concatenate([quat.IDENTITY, np.zeros(9)]))


def test_render() -> None:
    env = AstrobeeTumbleEnv(n_steps=20, render_mode="ansi")
    env.reset(seed=2)
    text = env.render()
    assert text.startswith("ds1 seed=2 step=0 t=0.0s pose=[")
    env.step(np.concatenate([quat.IDENTITY, np.zeros(9)]))
    assert "missing" in env.render()
    assert AstrobeeTumbleEnv(n_steps=20).render() is None


# ---------------------------------------------------------------------------- reward
def _cost(truth: np.ndarray, estimate: np.ndarray, weights=(1.0, 1.0, 10.0, 10.0)) -> float:
    """The documented cost, computed independently."""
    theta = float(quat.angle_between(truth[:4], quat.normalize(estimate[:4])))
    norms = [np.linalg.norm(estimate[s] - truth[s]) for s in (slice(4, 7), slice(7, 10), slice(10, 13))]
    return weights[0] * theta + sum(w * n for w, n in zip(weights[1:], norms))


@pytest.mark.parametrize("weights", [None, {"attitude": 2.0, "omega": 0.5}])
def test_reward_is_minus_the_documented_cost(weights: dict | None) -> None:
    env = gym.make(ENV_ID, n_steps=100, expose_truth=True, reward_weights=weights)
    w = (1.0, 1.0, 10.0, 10.0) if weights is None else (2.0, 1.0, 0.5, 10.0)
    rng = np.random.default_rng(5)
    obs, info = env.reset(seed=0)
    for _ in range(99):
        truth = info["truth"]
        estimate = truth + 0.05 * rng.standard_normal(13)
        estimate[:4] *= rng.uniform(0.5, 2.0)  # unnormalised
        obs, reward, _, _, info_next = env.step(estimate)
        assert reward == pytest.approx(-_cost(truth, estimate, w), rel=1e-12, abs=1e-14)
        assert reward < 0
        info = info_next


def test_reward_known_value_and_sign_safety() -> None:
    env = AstrobeeTumbleEnv(n_steps=20, expose_truth=True)
    _, info = env.reset(seed=0)
    truth = info["truth"]
    estimate = truth.copy()
    estimate[:4] = quat.multiply(quat.from_rotation_vector([0.0, 0.0, 0.1]), truth[:4])
    estimate[4:7] += [0.3, 0.0, -0.4]
    estimate[7:10] += [0.01, 0.0, 0.0]
    expected = -(0.1 + 0.5 + 0.1)
    _, reward, *_ = env.step(estimate)
    assert reward == pytest.approx(expected, rel=1e-12)
    negated = estimate.copy()
    negated[:4] *= -1
    scaled = estimate.copy()
    scaled[:4] *= 3.0
    rewards = []
    for action in (negated, scaled, list(estimate), estimate.astype(np.float32)):
        env.reset(seed=0)
        rewards.append(env.step(action)[1])
    assert rewards[0] == reward  # sign-safe, bit for bit
    assert rewards[1] == pytest.approx(reward, rel=1e-14)  # normalised
    assert rewards[2] == reward  # list input scores the same as an array
    assert rewards[3] == pytest.approx(reward, rel=1e-6)


def test_perfect_and_negated_estimates_score_zero() -> None:
    env = gym.make(ENV_ID, scenario="tumble-fast", n_steps=60, expose_truth=True)
    flip = np.array([-1.0] * 4 + [1.0] * 9)
    record = _run(env, 2, 60, lambda k, truth: truth * flip if k % 2 else truth)
    assert all(r == 0.0 for r in record["reward"])


# ---------------------------------------------------------------------------- checker and errors
def test_check_env_passes_with_only_the_action_space_recommendation() -> None:
    """Also with frames (``render_mode="rgb_array"``): ``check_env`` makes and renders every
    declared mode; ``human`` on a machine without a display says so (and draws off-screen)."""
    for render_mode in (None, "rgb_array"):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(gym.make(ENV_ID, render_mode=render_mode, n_steps=20).unwrapped)
        messages = [str(w.message) for w in caught if "render_mode='human' has no window" not in str(w.message)]
        normalized = [m for m in messages if "symmetric and normalized" in m]
        assert len(normalized) == 1, messages
        assert [m for m in messages if m not in normalized] == []


def test_passive_checker_is_silent_on_missing_measurements() -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env = gym.make(ENV_ID, n_steps=30, expose_truth=True)
        _run(env, 0, 30)
    assert [str(w.message) for w in caught] == []


@pytest.mark.parametrize(
    ("action", "pattern"),
    [
        (np.zeros(12), r"shape \(13,\)"),
        (np.zeros((2, 13)), r"shape \(13,\)"),
        (np.array([1.0] + [0.0] * 5 + [np.nan] + [0.0] * 6), r"finite: action\[6\] \(rz\) is nan"),
        (np.array([np.inf] + [0.0] * 12), r"finite: action\[0\] \(qw\) is inf"),
        ([1.0] + [0.0] * 8 + [np.nan] + [0.0] * 3, r"action\[9\] \(wz\)"),
        (np.zeros(13), "zero norm"),
        (np.zeros(13, dtype=np.float32), "zero norm"),
        ("estimate", "float array"),
    ],
)
def test_bad_actions_raise_value_error(action: object, pattern: str) -> None:
    env = gym.make(ENV_ID, n_steps=20)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=pattern):
        env.step(action)


@pytest.mark.parametrize(
    ("kwargs", "error", "pattern"),
    [
        ({"dropout": 1.5}, ConfigError, r"'dropout' must be a number in \[0, 1\]"),
        ({"noise_scale": -1.0}, ConfigError, r"'noise_scale' must be a finite number in \[0, 1e\+06\]"),
        ({"noise_scale": 1e300}, ConfigError, r"'noise_scale' must be a finite number in \[0, 1e\+06\]"),
        ({"measurement_every": 0}, ConfigError, "'measurement_every' must be an integer >= 1"),
        ({"bogus": 1}, ConfigError, "unknown scenario field.*bogus"),
        ({"scenario": "ds3"}, UnknownScenarioError, "unknown scenario 'ds3'; valid scenarios: ds1, ds2"),
        ({"reward_weights": {"spin": 1.0}}, ValueError, r"unknown reward weight.*spin"),
        ({"reward_weights": {"omega": -1.0}}, ValueError, "reward weight 'omega' must be a finite number >= 0"),
        ({"chunk_size": 0}, ValueError, "chunk_size"),
    ],
)
def test_invalid_kwargs_name_the_field(kwargs: dict, error: type, pattern: str) -> None:
    with pytest.raises(error, match=pattern):
        gym.make(ENV_ID, **kwargs)


def test_invalid_render_mode() -> None:
    with pytest.raises(ValueError, match=r"render_mode must be None or one of \['ansi', 'rgb_array', 'human'\]"):
        AstrobeeTumbleEnv(render_mode="video")


def test_negative_seed() -> None:
    env = AstrobeeTumbleEnv(n_steps=20)
    with pytest.raises((ValueError, gym.error.Error), match="greater or equal to zero|non-negative"):
        env.reset(seed=-1)


@pytest.mark.parametrize("value", ["no", "False", 0, None])
def test_expose_truth_must_be_a_bool(value: object) -> None:
    with pytest.raises(ValueError, match=r"expose_truth must be True or False \(got"):
        gym.make("AstrobeeTumble-v0", expose_truth=value)


# ---------------------------------------------------------------------------- issue 34, finding 7: loose inputs
@pytest.mark.parametrize("dtype", [str, bool, complex])
def test_actions_of_string_bool_or_complex_dtype_are_refused(dtype: type) -> None:
    """They were accepted: strings parsed as numbers, bools read as 0/1, and complex numbers
    lost their imaginary part with a warning."""
    env = AstrobeeTumbleEnv(n_steps=20)
    env.reset(seed=0)
    action = np.eye(1, 13)[0].astype(dtype)
    pattern = rf"^action must be a float array of shape \(13,\) \(a real integer or floating dtype; got dtype {action.dtype}\)$"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match=pattern):
            env.step(action)


def test_an_action_beyond_float64_is_a_value_error() -> None:
    """It was an OverflowError from numpy's conversion."""
    env = AstrobeeTumbleEnv(n_steps=20)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"^action\[4\] is an integer of 401 digits, beyond float64's range"):
        env.step([1, 0, 0, 0, 10**400] + [0] * 8)


@pytest.mark.parametrize("component", [0, 4, 12])
def test_actions_beyond_action_limit_are_refused_not_scored_minus_inf(component: int) -> None:
    """1e308 gave the reward -inf (and a quaternion of 1e200 was scored as pi rad off)."""
    env = AstrobeeTumbleEnv(n_steps=20)
    env.reset(seed=0)
    action = np.eye(1, 13)[0]
    action[component] = 1e308 if component else 1e200
    with pytest.raises(ValueError, match=r"^action must be within \+-ACTION_LIMIT = 1e\+150: action\["):
        env.step(action)


def test_rewards_are_finite_at_the_limits() -> None:
    """With every weight at WEIGHT_LIMIT and every component at +-ACTION_LIMIT, the reward is
    finite; a weight beyond the limit, or not a real number, is refused."""
    from fkn_bench.envs.rewards import WEIGHT_LIMIT
    from fkn_bench.envs.spaces import ACTION_LIMIT

    weights = dict.fromkeys(("attitude", "position", "omega", "velocity"), WEIGHT_LIMIT)
    env = AstrobeeTumbleEnv(n_steps=20, reward_weights=weights)
    env.reset(seed=0)
    reward = env.step(np.where(np.arange(13) % 2, ACTION_LIMIT, -ACTION_LIMIT))[1]
    assert math.isfinite(reward) and reward < -1e150
    for bad, words in ((1e7, "at most WEIGHT_LIMIT = 1e\\+06 \\(got 10000000.0\\)"), (10**400, "at most WEIGHT_LIMIT"),
                       ("1.0", "a real number \\(got '1.0'\\)"), (True, "a real number \\(got True\\)")):
        with pytest.raises(ValueError, match=rf"^reward weight 'omega' must be (a finite number >= 0 and )?{words}"):
            AstrobeeTumbleEnv(n_steps=20, reward_weights={"omega": bad})
