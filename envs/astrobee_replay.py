"""``AstrobeeReplay-v0``: online pose-and-twist estimation on a recorded trajectory (MCAP)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from fkn_bench.envs.astrobee_tumble import AstrobeeTumbleEnv
from fkn_bench.envs.episodes import Episodes

__all__ = ["AstrobeeReplayEnv"]


class AstrobeeReplayEnv(AstrobeeTumbleEnv):
    """Estimate the pose and twist of a recorded trajectory from (recorded or synthesised) poses.

    ## Description

    The ground truth comes from an MCAP recording: an fkn-bench recording (``fkn-bench record``),
    an Astrobee simulation log (``<robot>/loc/truth/pose``, 62.5 Hz) or any ROS 1 / ROS 2 /
    Foxglove JSON pose topic. It is resampled onto the scenario's time grid (slerp for the
    attitude; see :mod:`fkn_bench.envs.replay`). Measurements are either a recorded pose
    topic, used as is, or synthesised from the truth with the scenario's noise model, seeded by
    the episode seed. Everything else follows ``AstrobeeTumble-v0``.

    ## Observation Space, Action Space, Rewards and Episode End

    As ``AstrobeeTumble-v0``, against the replayed truth: observations carry the time in s from
    the first truth message, the episode starts at that message and is truncated when the last
    replayed step has been observed.

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
      ``quaternion_tolerance``: as :func:`fkn_bench.envs.replay.read_recording` (every keyword
      that it takes; its defaults).
    * ``expose_truth``: put the true 13-dim state in ``info["truth"]``.
    * ``reward_weights``, ``render_mode`` (``None``, ``"ansi"``, ``"rgb_array"``, ``"human"``): as
      ``AstrobeeTumble-v0``.

    ## Seeding

    ``reset(seed=s)`` synthesises measurements with episode seed ``s`` (the same as
    ``fkn_bench.envs.replay.load_episodes(path, seed=s)``); an unseeded ``reset`` draws the episode
    seed from ``self.np_random``. Recorded measurements are the same for every seed.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        expose_truth: bool = False,
        reward_weights: Mapping[str, float] | None = None,
        render_mode: str | None = None,
        **recording_options: Any,
    ) -> None:
        from fkn_bench.envs.replay import read_recording

        self._check_render_mode(render_mode)  # before reading the recording
        self.trajectory = read_recording(path, **recording_options)
        self.report = self.trajectory.report
        super().__init__(self.trajectory.scenario, expose_truth=expose_truth, reward_weights=reward_weights,
                         render_mode=render_mode)

    def _new_stream(self, seed: int) -> Episodes:
        return self.trajectory.episodes(seed)

    def _load_chunk(self) -> None:
        """The whole replayed episode is one chunk (loaded by ``reset``)."""
        e = self._stream
        self._chunk_start = 0
        self._times, self._truth, self._meas, self._valid = e.times, e.truth, e.measurements, e.valid
        self._truth_rows = self._truth[0].tolist()

    def _render_name(self) -> tuple[str, int]:
        return f"replay {self.report.path.name}", 2
