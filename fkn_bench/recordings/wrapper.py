"""A Gymnasium wrapper that records an environment loop to MCAP, one file per episode.

What is recorded (see :mod:`fkn_bench.recordings.writer` for topics and conventions):

* observations as the measured pose (``{"pose", "valid", "time"}`` dicts as the Astrobee
  environments return, or bare ``(7,)`` poses with NaN when missing);
* actions as the estimated pose and twist at the time of the observation they answer (the
  13-dim state estimate of the Astrobee environments); the last observation of an episode has no
  action;
* ``info["truth"]`` as the true pose and twist, when the environment provides it (make the Astrobee
  environments with ``expose_truth=True``).

Times come from the observations' ``time``; without one, step ``k`` is at ``k * dt`` (``dt``
argument, else the environment's ``scenario.dt``). A file is written (atomically) when an episode
ends (terminated or truncated), when ``reset`` starts a new one, or on ``close``; episodes with no
step are not written.

Example::

    env = RecordMcap(gym.make("AstrobeeTumble-v0", expose_truth=True, n_steps=500), "runs/ep{episode}.mcap")
    obs, info = env.reset(seed=0)
    ...  # env.step(estimate) until truncated
    env.close()
    env.recorded_paths  # [PosixPath('runs/ep0.mcap')]
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from fkn_bench.recordings.writer import episode_metadata, write_recording

__all__ = ["RecordMcap"]


class RecordMcap(gym.Wrapper):
    """Record each episode of ``env`` to an MCAP file (see module docstring).

    Args:
        env: the environment (single, not vectorised).
        path: output file. ``{episode}`` (0, 1, ...) and ``{seed}`` (the ``episode_seed`` in the
            reset info, else the episode number) are filled in; without placeholders, the first
            episode goes to ``path`` and episode ``n`` to ``<stem>-<n><suffix>``.
        estimator: an :class:`~fkn_bench.estimators.Estimator` (or a mapping of strings) for the
            ``fkn_bench.estimator`` metadata.
        dt: step in s for observations without a time (default: the environment's scenario's).
        metadata: extra metadata records ``{name: {key: value}}``.
        writer_options: options of :func:`~fkn_bench.recordings.writer.write_recording`
            (``namespace``, ``frame_id``, ``foxglove``, ``compression``, ``start_epoch_ns``, ...).
    """

    def __init__(
        self,
        env: gym.Env,
        path: str | Path,
        *,
        estimator: Any = None,
        dt: float | None = None,
        metadata: Mapping[str, Mapping[str, str]] | None = None,
        **writer_options: Any,
    ) -> None:
        super().__init__(env)
        self.path_template = str(path)
        self.estimator = estimator
        scenario = getattr(env.unwrapped, "scenario", None)
        self._dt = float(dt) if dt is not None else getattr(scenario, "dt", None)
        self._metadata = dict(metadata or {})
        self._writer_options = writer_options
        self.recorded_paths: list[Path] = []
        self._episode = -1
        self._seed: Any = None
        self._observations: list[tuple[float, np.ndarray, np.ndarray | None]] | None = None  # time, pose, truth
        self._estimates: list[np.ndarray] = []

    def _observe(self, obs: Any, info: Mapping[str, Any]) -> None:
        assert self._observations is not None
        if isinstance(obs, Mapping):  # a Gymnasium observation dict, or a bare (7,) pose (NaN when missing)
            pose, valid, time = obs["pose"], obs.get("valid", True), obs.get("time")
        else:
            pose, valid, time = obs, True, None
        pose = np.asarray(pose, dtype=float).reshape(7)
        if time is None:
            if self._dt is None:
                raise ValueError(
                    "the observations carry no 'time' and the environment has no scenario.dt; pass dt= to RecordMcap"
                )
            time = len(self._observations) * self._dt
        truth = info.get("truth")
        truth = None if truth is None else np.array(truth, dtype=float).reshape(13)
        self._observations.append((float(time), pose if valid else np.full(7, np.nan), truth))

    def _output_path(self) -> Path:
        template = self.path_template
        if "{episode" in template or "{seed" in template:
            seed = self._episode if self._seed is None else self._seed
            return Path(template.format(episode=self._episode, seed=seed))
        path = Path(template)
        return path if self._episode == 0 else path.with_name(f"{path.stem}-{self._episode}{path.suffix}")

    def _flush(self) -> None:
        observations, self._observations = self._observations, None
        if not observations or not self._estimates:
            return
        path = self._output_path()
        times, measurements, truth = zip(*observations)
        n, k = len(times), len(self._estimates)
        estimates = np.full((n, 13), np.nan)
        estimates[:k] = self._estimates
        scenario = getattr(self.env.unwrapped, "scenario", None)
        if not (hasattr(scenario, "to_dict") and hasattr(scenario, "config_hash")):
            scenario = None
        spec = getattr(self.env, "spec", None)
        episode = {
            "seed": "" if self._seed is None else str(self._seed),
            "episode": str(self._episode),
            "n_steps": str(n),
            "environment": spec.id if spec is not None else type(self.env.unwrapped).__name__,
            "source": "fkn_bench.recordings.RecordMcap",
        }
        write_recording(
            path,
            times=np.array(times),
            truth=None if any(t is None for t in truth) else np.array(truth),
            measurements=np.array(measurements),  # written where not NaN
            estimates=estimates,
            estimate_mask=np.arange(n) < k,
            metadata=episode_metadata(episode, scenario=scenario, estimator=self.estimator, extra=self._metadata),
            **self._writer_options,
        )
        self.recorded_paths.append(path)

    # ------------------------------------------------------------------ Gymnasium API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        self._flush()
        obs, info = self.env.reset(seed=seed, options=options)
        self._episode += 1
        self._seed, self._observations, self._estimates = info.get("episode_seed"), [], []
        self._observe(obs, info)
        return obs, info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        if self._observations is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._estimates.append(np.array(action, dtype=float).reshape(13))
        self._observe(obs, info)
        if terminated or truncated:
            self._flush()
        return obs, reward, terminated, truncated, info

    def close(self) -> None:
        self._flush()
        super().close()
