"""``AstrobeeTumble-v0``: online pose-and-twist estimation of a tumbling Astrobee."""

from __future__ import annotations

import math
import numbers
from collections import deque
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from fkn_bench.envs.episodes import EpisodeStream, measurement_covariances
from fkn_bench.envs.rendering import HISTORY_STEPS
from fkn_bench.envs.rewards import DEFAULT_WEIGHTS, WEIGHT_LIMIT, attitude_error_angle, estimate_cost_scalar
from fkn_bench.envs.spaces import MeasuredPose, action_space, action_values, observation_space
from fkn_bench.inputs import check_count, check_seed, describe
from fkn_bench.scenarios import Scenario, get_scenario
from fkn_bench.types import ArrayF

__all__ = ["AstrobeeTumbleEnv", "EPISODE_SEED_BOUND", "episode_seed_for_reset"]

EPISODE_SEED_BOUND = 2**31
"""Episode seeds drawn by an unseeded ``reset()`` lie in ``[0, EPISODE_SEED_BOUND)``."""


def episode_seed_for_reset(seed: int | None, np_random: np.random.Generator) -> int:
    """The episode seed of ``reset(seed=...)``: ``seed`` itself (an integer in ``[0, 2**63)``,
    :func:`fkn_bench.inputs.check_seed`), else one drawn from the environment's ``np_random``
    (seeded by Gymnasium on the first reset)."""
    if seed is None:
        return int(np_random.integers(EPISODE_SEED_BOUND))
    return check_seed(seed)


class _EpisodeWalk:
    """What the single and the vector environment share: their configuration, and the walk
    through episode data (batch first) that a stream delivers ``chunk_size`` steps at a time."""

    metadata: dict[str, Any]

    def _check_render_mode(self, render_mode: str | None) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            modes = self.metadata["render_modes"]
            raise ValueError(f"render_mode must be None or one of {modes} (got {render_mode!r})")

    def _configure(
        self,
        scenario: str | Scenario,
        expose_truth: bool,
        reward_weights: Mapping[str, float] | None,
        render_mode: str | None,
        chunk_size: int,
        overrides: Mapping[str, Any],
    ) -> None:
        self.scenario: Scenario = get_scenario(scenario, **overrides)
        self._check_render_mode(render_mode)
        chunk_size = check_count(chunk_size, "chunk_size")
        self.render_mode = render_mode
        if not isinstance(expose_truth, (bool, np.bool_)):  # bool("no") is True: no truthiness here
            raise ValueError(f"expose_truth must be True or False (got {expose_truth!r})")
        self.expose_truth = bool(expose_truth)
        self.reward_weights = _check_weights(reward_weights)
        self._chunk_size = chunk_size
        self._stream: Any = None
        self._index = 0

    def _start(self, stream: Any) -> None:
        self._stream = stream
        self._index = 0
        self._load_chunk()

    def _load_chunk(self) -> None:
        self._chunk_start = self._stream.index
        self._times, self._truth, self._meas, self._valid = self._stream.advance(self._chunk_size)

    def _next_step(self) -> bool:
        """Go to the next step (loading the next chunk when needed); True at the episode's last."""
        self._index += 1
        if self._index - self._chunk_start >= len(self._times):
            self._load_chunk()
        return self._index == self.scenario.n_steps - 1


class AstrobeeTumbleEnv(_EpisodeWalk, gym.Env[dict[str, Any], ArrayF]):
    """Estimate the pose and twist of a tumbling Astrobee from noisy pose measurements.

    ## Description

    A free-flying Astrobee rotates (forced at a constant world-frame rate, as in the
    FlexKalmanNet paper, or tumbling torque-free with its flight inertia) while a pose sensor
    reports its attitude and position with noise, at a configurable rate, with dropout, data
    gaps, outliers and quaternion sign flips. The agent is a state estimator: at every step it
    receives the current observation and answers with its 13-dim state estimate for that time,
    which is scored against the hidden ground truth.

    ## Observation Space

    A ``Dict``:

    | Key     | Space                   | Meaning                                                   |
    |---------|-------------------------|-----------------------------------------------------------|
    | `pose`  | `PoseBox(7,)` float64   | measured `[qw, qx, qy, qz, rx, ry, rz]` (wxyz, m); all NaN when missing |
    | `valid` | `Discrete(2)`           | 1 when `pose` holds a measurement, else 0                 |
    | `time`  | `Box(0, T dt, ())`      | time of the observation, s                                |

    The measured quaternion may arrive as ``-q`` (scenarios with sign flips).

    ## Action Space

    ``Box(13,)`` float64: the estimate ``[qw, qx, qy, qz, rx, ry, rz, wx, wy, wz, vx, vy, vz]``
    of the state at the time of the current observation (attitude body-to-world, position m,
    world-frame angular velocity rad/s, velocity m/s). The quaternion is normalised for scoring.
    ``step`` refuses with a one-line ``ValueError`` naming the argument
    (:func:`~fkn_bench.envs.spaces.validate_actions`; the vector environment and the estimators'
    ``step`` follow the same rules, :mod:`fkn_bench.inputs`):

    | Action                                                      | Rule                                                     |
    |-------------------------------------------------------------|----------------------------------------------------------|
    | a real integer or floating dtype (int, float32, float64...) | converted to float64                                     |
    | strings (also `"1.0"`), bools, complex numbers, objects     | refused, naming the dtype                                |
    | a shape other than `(13,)` (0-d, `(1, 13)`, ragged lists)   | refused, naming the shape                                |
    | a value float64 cannot hold (`10**400`, a long double)      | refused, naming the entry                                |
    | a NaN or +-inf entry                                        | refused, naming the component                            |
    | `abs(entry) > ACTION_LIMIT` (1e150)                         | refused, naming the component: its reward would overflow |
    | a quaternion of squared norm < 1e-12                        | refused (its attitude cannot be scored)                  |

    ## Rewards

    ``-(theta + 1 |dr| + 10 |dw| + 10 |dv|)`` with ``theta`` the sign-safe attitude error angle
    (rad) and ``|.|`` Euclidean norms (m, rad/s, m/s) of the estimate's error at the scored time;
    weights set by ``reward_weights`` (see :mod:`fkn_bench.envs.rewards`). The estimate passed
    to ``step`` is scored against the truth at the time of the observation it answers. The
    reward is always finite: actions are bounded by ``ACTION_LIMIT`` and weights by
    ``WEIGHT_LIMIT`` (1e6).

    ## Starting State

    The scenario draws the initial attitude (uniformly random by default), position and rates
    from the episode seed; ``reset`` returns the observation at step 0.

    ## Episode End

    No termination. The episode is truncated when the last sample of the scenario's episode
    (``n_steps``, 16000 for ``ds1``) has been observed: the step that returns it has
    ``truncated=True``, and its estimate is not scored.

    ## Arguments

    ```python
    gym.make("AstrobeeTumble-v0", scenario="ds1", expose_truth=False, reward_weights=None,
             render_mode=None, **overrides)
    ```

    * ``scenario``: registered name (``fkn-bench scenarios`` lists them) or a ``Scenario``.
    * ``**overrides``: any scenario field, e.g. ``noise_scale=5.0``, ``measurement_every=10``,
      ``dropout=0.2``, ``sign_flip_probability=0.5``, ``dynamics="free"``.
    * ``expose_truth``: put the true 13-dim state in ``info["truth"]`` (never in the observation).
    * A scenario with ``measurement_covariance=True`` puts the covariance the step's measurement
      states, ``(6, 6)`` in the error order ``[dtheta (rad), dr (m)]`` (NaN without a
      measurement), in ``info["measurement_covariance"]``.
    * ``reward_weights``: mapping with keys ``attitude``, ``position``, ``omega``, ``velocity``,
      each a real number in ``[0, 1e6]`` (not a string or a bool).
    * ``render_mode``: ``None``, ``"ansi"`` (a one-line text summary), ``"rgb_array"`` (frames,
      ``uint8 (H, W, 3)``: the body axes of the true, estimated and measured attitude and the
      attitude error; see :mod:`fkn_bench.envs.rendering`) or ``"human"`` (the same in a window,
      drawn at every step; needs a display). ``metadata["render_fps"]`` is the scenario's rate,
      ``1 / dt``, so that ``gymnasium.wrappers.RecordVideo`` plays in real time.

    ## Seeding

    ``reset(seed=s)`` generates exactly episode ``s`` of the scenario (the same data as
    ``fkn_bench.envs.generate_episodes(scenario, [s])``); an unseeded ``reset`` draws the next
    episode seed from ``self.np_random``. A seed is an integer in ``[0, 2**63)``: a Python
    ``int`` or a numpy integer (Gymnasium's rule, "a non-negative int", bounded because episode
    seeds are stored as int64; :func:`fkn_bench.inputs.check_seed`). Anything else (a bool, a
    float, NaN, a string, an array, a negative seed or one of 2**63 or more) raises a one-line
    ``ValueError`` naming ``seed``, as the vector environment does.
    """

    metadata = {"render_modes": ["ansi", "rgb_array", "human"], "render_fps": 10}

    def __init__(
        self,
        scenario: str | Scenario = "ds1",
        *,
        expose_truth: bool = False,
        reward_weights: Mapping[str, float] | None = None,
        render_mode: str | None = None,
        chunk_size: int = 512,
        **overrides: Any,
    ) -> None:
        self._configure(scenario, expose_truth, reward_weights, render_mode, chunk_size, overrides)
        self.observation_space = observation_space(self.scenario.n_steps, self.scenario.dt)
        self.action_space = action_space()
        self.episode_seed: int | None = None
        self._setup_rendering()

    # ------------------------------------------------------------------ rendering
    def _setup_rendering(self) -> None:
        """Frames at the scenario's own rate (``render_fps`` = 1/dt, 1 to 60); a ``human``
        window needs a display, checked here: without one, a warning at ``gym.make`` and nothing
        drawn (Gymnasium's ``check_env`` makes every declared mode, so this must not fail)."""
        self.metadata = {**type(self).metadata, "render_fps": int(min(60, max(1, round(1.0 / self.scenario.dt))))}
        self._renderer: Any = None
        self._drawn = self.render_mode in ("rgb_array", "human")
        self._shown_estimate: ArrayF | None = None  # the latest action and the step it answered
        self._shown_step = 0
        self._shown_truth: ArrayF | None = None
        self._shown_measured = False
        self._latest_measurement: ArrayF | None = None
        self._error_history: deque[tuple[float, float]] = deque(maxlen=HISTORY_STEPS)
        self._window = self.render_mode == "human"
        if self._window:
            import warnings

            from fkn_bench.envs.rendering import display_problem

            problem = display_problem()
            if problem is not None:
                warnings.warn(problem, RuntimeWarning, stacklevel=3)
                self._window = False

    def _note_observation(self) -> None:
        """Remember what a frame shows of the current observation (only when rendering)."""
        i = self._index - self._chunk_start
        self._shown_step, self._shown_time = self._index, float(self._times[i])
        self._shown_truth = np.array(self._truth[0, i])
        self._shown_measured = bool(self._valid[0, i])
        if self._shown_measured:
            self._latest_measurement = np.array(self._meas[0, i])

    def _frame_state(self) -> Any:
        from fkn_bench.envs.rendering import FrameState

        name, _ = self._render_name()
        return FrameState(title=f"{name} seed {self.episode_seed}", step=self._shown_step, time=self._shown_time,
                          truth=self._shown_truth, estimate=self._shown_estimate,
                          measurement=self._latest_measurement, measured_now=self._shown_measured,
                          history=tuple(np.array(self._error_history).reshape(-1, 2).T))

    def _new_stream(self, seed: int) -> Any:
        """The data of episode ``seed``: an object with ``index`` and ``advance(n) -> (times,
        truth, measurements, valid)`` (:class:`~fkn_bench.envs.episodes.EpisodeStream`)."""
        return EpisodeStream(self.scenario, [seed])

    # ------------------------------------------------------------------ episode data
    def _load_chunk(self) -> None:
        super()._load_chunk()
        self._truth_rows = self._truth[0].tolist()  # Python floats for the fast reward path

    def _observation(self) -> dict[str, Any]:
        i = self._index - self._chunk_start
        return {
            "pose": self._meas[0, i].copy().view(MeasuredPose),
            "valid": np.int64(self._valid[0, i]),
            "time": np.array(self._times[i]),
        }

    def _info(self) -> dict[str, Any]:
        info: dict[str, Any] = {"step": self._index, "episode_seed": self.episode_seed}
        if self.expose_truth:
            info["truth"] = self._truth[0, self._index - self._chunk_start].copy()
        if self.scenario.measurement_covariance:  # what the measurement states of its own noise
            i = self._index - self._chunk_start
            info["measurement_covariance"] = measurement_covariances(
                self.scenario, self._index, self._valid[0:1, i : i + 1])[0, 0]
        return info

    # ------------------------------------------------------------------ Gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        seed = None if seed is None else check_seed(seed)  # before Gymnasium's own check: the same rule as the vector env
        super().reset(seed=seed)
        self.episode_seed = episode_seed_for_reset(seed, self.np_random)
        self._start(self._new_stream(self.episode_seed))
        if self._drawn:
            self._shown_estimate, self._latest_measurement = None, None
            self._error_history.clear()
            self._note_observation()
            if self.render_mode == "human":
                self.render()
        return self._observation(), self._info()

    def step(self, action: ArrayF) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        if self._stream is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        if self._index >= self.scenario.n_steps - 1:
            raise gym.error.ResetNeeded("the episode was truncated; call reset() before step()")
        values = action_values(action)
        truth = self._truth_rows[self._index - self._chunk_start]
        reward = -estimate_cost_scalar(truth, values, self.reward_weights)
        if self._drawn:  # a frame shows the estimate against the truth of the step it answers
            self._note_observation()
            self._shown_estimate = np.array(values)
            error = attitude_error_angle(self._shown_truth[None, :4], self._shown_estimate[None, :4])
            self._error_history.append((self._shown_time, float(np.degrees(error[0]))))
        truncated = self._next_step()
        if self.render_mode == "human":
            self.render()
        return self._observation(), reward, False, truncated, self._info()

    def _render_name(self) -> tuple[str, int]:
        """What ``render`` calls the episode, and the decimals of its time."""
        return self.scenario.name, 1

    def render(self) -> Any:
        """``ansi``: a one-line summary; ``rgb_array``: the frame, ``uint8 (H, W, 3)``
        (:mod:`fkn_bench.envs.rendering`); ``human``: the frame in a window (drawn by ``reset``
        and ``step`` too). None before the first ``reset``."""
        if self.render_mode is None or self._stream is None:
            return None
        if self.render_mode == "human" and not self._window:  # no display (warned at construction)
            return None
        if self.render_mode in ("rgb_array", "human"):
            if self._renderer is None:
                from fkn_bench.envs.rendering import PoseRenderer

                self._renderer = PoseRenderer(interactive=self._window, fps=self.metadata["render_fps"])
            if self.render_mode == "human":
                self._renderer.draw(self._frame_state())
                return None
            return self._renderer.rgb_array(self._frame_state())
        i = self._index - self._chunk_start
        shown = "missing" if not self._valid[0, i] else np.array2string(self._meas[0, i], precision=3)
        name, digits = self._render_name()
        return f"{name} seed={self.episode_seed} step={self._index} t={self._times[i]:.{digits}f}s pose={shown}"

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        super().close()


def _check_weights(weights: Mapping[str, float] | None) -> dict[str, float]:
    """The reward weights: :data:`~fkn_bench.envs.rewards.DEFAULT_WEIGHTS` updated with
    ``weights``, each a real number (an ``int``, a ``float`` or a numpy one; not a string, a bool
    or a complex number) in ``[0, WEIGHT_LIMIT]``; ``ValueError`` naming the key otherwise."""
    weights = weights or {}
    unknown = set(weights) - set(DEFAULT_WEIGHTS)
    if unknown:
        raise ValueError(f"unknown reward weight(s) {sorted(unknown)}; valid keys: {sorted(DEFAULT_WEIGHTS)}")
    merged = dict(DEFAULT_WEIGHTS)
    for key, value in weights.items():
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
            raise ValueError(f"reward weight '{key}' must be a real number (got {describe(value)})")
        merged[key] = float(value) if abs(value) <= WEIGHT_LIMIT else math.inf  # (10**400: no OverflowError)
    for key, value in merged.items():
        if not 0 <= value <= WEIGHT_LIMIT:
            raise ValueError(
                f"reward weight '{key}' must be a finite number >= 0 and at most WEIGHT_LIMIT = {WEIGHT_LIMIT:g} "
                f"(got {describe(weights.get(key, value))})"
            )
    return merged
