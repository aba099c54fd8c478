"""``AstrobeeReplay-v0``: online pose-and-twist estimation on a recorded trajectory (MCAP)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from fkn_bench.envs.astrobee_tumble import _check_weights, episode_seed_for_reset
from fkn_bench.envs.rewards import estimate_cost_scalar
from fkn_bench.envs.spaces import MeasuredPose, action_space, action_values, observation_space
from fkn_bench.scenarios import Scenario
from fkn_bench.types import ArrayF

__all__ = ["AstrobeeReplayEnv"]


class AstrobeeReplayEnv(gym.Env[dict[str, Any], ArrayF]):
    """Estimate the pose and twist of a recorded trajectory from (recorded or synthesised) poses.

    ## Description

    The ground truth comes from an MCAP recording: an fkn-bench recording (``fkn-bench record``),
    an Astrobee simulation log (``<robot>/loc/truth/pose``, 62.5 Hz) or any ROS 1 / ROS 2 /
    Foxglove JSON pose topic. It is resampled onto the scenario's time grid (slerp for the
    attitude; see :mod:`fkn_bench.recordings.replay`). Measurements are either a recorded pose
    topic, used as is, or synthesised from the truth with the scenario's noise model, seeded by
    the episode seed. Everything else follows ``AstrobeeTumble-v0``.

    ## Observation Space

    A ``Dict`` with ``pose`` (``PoseBox(7,)``: measured ``[qw, qx, qy, qz, rx, ry, rz]``, all NaN
    when missing), ``valid`` (``Discrete(2)``) and ``time`` (``Box(0, T dt, ())``, s from the
    first truth message), as in ``AstrobeeTumble-v0``.

    ## Action Space

    ``Box(13,)`` float64: the state estimate ``[q(wxyz), r, w (world frame), v]`` at the time of
    the current observation; validated as in ``AstrobeeTumble-v0``.

    ## Rewards

    ``-(theta + 1 |dr| + 10 |dw| + 10 |dv|)`` against the replayed truth (``reward_weights``
    changes the weights; see :mod:`fkn_bench.envs.rewards`).

    ## Starting State

    The first truth message of the recording.

    ## Episode End

    Truncated when the last replayed step has been observed (the step that returns it has
    ``truncated=True``); its estimate is not scored.

    ## Arguments

    ```python
    gym.make("AstrobeeReplay-v0", path="run.mcap", truth_topic=None, measurement_topic=None,
             twist_topic="auto", scenario=None, dt=None, repair=False, expose_truth=False,
             reward_weights=None, render_mode=None)
    ```

    * ``path``: the ``.mcap`` file.
    * ``truth_topic``: pose topic of the truth; None finds an fkn-bench recording's truth or
      Astrobee's ``<robot>/loc/truth/pose``.
    * ``measurement_topic``: pose topic used as measurements; None synthesises them.
    * ``twist_topic``, ``scenario``, ``dt``, ``repair``, ``time_source``, ``twist_frame``,
      ``quaternion_tolerance``: as :func:`fkn_bench.recordings.read_recording`.
    * ``expose_truth``: put the true 13-dim state in ``info["truth"]``.
    * ``reward_weights``, ``render_mode`` (``None`` or ``"ansi"``): as ``AstrobeeTumble-v0``.

    ## Seeding

    ``reset(seed=s)`` synthesises measurements with episode seed ``s`` (the same as
    ``fkn_bench.recordings.load_episodes(path, seed=s)``); an unseeded ``reset`` draws the episode
    seed from ``self.np_random``. Recorded measurements are the same for every seed.
    """

    metadata = {"render_modes": ["ansi"], "render_fps": 10}

    def __init__(
        self,
        path: str | Path,
        *,
        truth_topic: str | None = None,
        measurement_topic: str | None = None,
        twist_topic: str | None = "auto",
        scenario: str | Scenario | None = None,
        dt: float | str | None = None,
        repair: bool = False,
        time_source: str = "auto",
        twist_frame: str = "auto",
        quaternion_tolerance: float = 1e-6,
        expose_truth: bool = False,
        reward_weights: Mapping[str, float] | None = None,
        render_mode: str | None = None,
    ) -> None:
        from fkn_bench.recordings.replay import read_recording

        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']} (got {render_mode!r})")
        self.trajectory = read_recording(
            path,
            truth_topic=truth_topic,
            measurement_topic=measurement_topic,
            twist_topic=twist_topic,
            scenario=scenario,
            dt=dt,
            repair=repair,
            time_source=time_source,
            twist_frame=twist_frame,
            quaternion_tolerance=quaternion_tolerance,
        )
        self.scenario: Scenario = self.trajectory.scenario
        self.report = self.trajectory.report
        self.render_mode = render_mode
        self.expose_truth = bool(expose_truth)
        self.reward_weights = _check_weights(reward_weights)
        self.observation_space = observation_space(self.scenario.n_steps, self.scenario.dt)
        self.action_space = action_space()
        self._truth = self.trajectory.truth
        self._truth_rows = self._truth.tolist()
        self._times = self.trajectory.times
        self._meas: ArrayF | None = None
        self._valid: np.ndarray | None = None
        self._index = 0
        self.episode_seed: int | None = None

    def _observation(self) -> dict[str, Any]:
        assert self._meas is not None and self._valid is not None
        i = self._index
        return {
            "pose": self._meas[i].copy().view(MeasuredPose),
            "valid": np.int64(self._valid[i]),
            "time": np.array(self._times[i]),
        }

    def _info(self) -> dict[str, Any]:
        info: dict[str, Any] = {"step": self._index, "episode_seed": self.episode_seed}
        if self.expose_truth:
            info["truth"] = self._truth[self._index].copy()
        return info

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        super().reset(seed=seed)
        self.episode_seed = episode_seed_for_reset(seed, self.np_random)
        episodes = self.trajectory.episodes(self.episode_seed)
        self._meas, self._valid = episodes.measurements[0], episodes.valid[0]
        self._index = 0
        return self._observation(), self._info()

    def step(self, action: ArrayF) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        if self._meas is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        if self._index >= self.scenario.n_steps - 1:
            raise gym.error.ResetNeeded("the episode was truncated; call reset() before step()")
        values = action_values(action)
        reward = -estimate_cost_scalar(self._truth_rows[self._index], values, self.reward_weights)
        self._index += 1
        truncated = self._index == self.scenario.n_steps - 1
        return self._observation(), reward, False, truncated, self._info()

    def render(self) -> str | None:
        if self.render_mode != "ansi" or self._meas is None or self._valid is None:
            return None
        i = self._index
        shown = "missing" if not self._valid[i] else np.array2string(self._meas[i], precision=3)
        return f"replay {self.report.path.name} seed={self.episode_seed} step={i} t={self._times[i]:.2f}s pose={shown}"
