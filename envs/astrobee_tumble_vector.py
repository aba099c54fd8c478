"""Batched ``AstrobeeTumble-v0`` for ``gym.make_vec(..., vectorization_mode="vector_entry_point")``."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium.error import ResetNeeded
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from fkn_bench.envs.astrobee_tumble import _EpisodeWalk, episode_seed_for_reset
from fkn_bench.envs.episodes import EpisodeStream
from fkn_bench.envs.rewards import cost_and_quaternion_norm, unit_quaternions
from fkn_bench.envs.spaces import ACTION_LIMIT, QUATERNION_NORM_MIN, MeasuredPose, action_space, observation_space, pose_space, validate_actions
from fkn_bench.inputs import check_count, check_seed
from fkn_bench.scenarios import Scenario
from fkn_bench.types import ArrayF

__all__ = ["AstrobeeTumbleVectorEnv", "CHUNK_SAMPLES"]

CHUNK_SAMPLES = 2**18
"""Env-steps generated per chunk by default (``chunk_size=None``: ``CHUNK_SAMPLES // num_envs``
steps, between 16 and 512): 256 steps at 1024 environments, the fastest of 32-512 there with the
chunks' generation included (``fkn-bench bench run -k env_step``)."""


class AstrobeeTumbleVectorEnv(_EpisodeWalk, VectorEnv):
    """``num_envs`` Astrobee episodes stepped together with numpy arrays.

    Observations, actions and rewards are those of
    :class:`~fkn_bench.envs.astrobee_tumble.AstrobeeTumbleEnv` with a leading ``num_envs`` axis
    (``pose (N, 7)``, ``valid (N,)``, ``time (N,)``; actions ``(N, 13)``). Sub-environment ``i``
    of ``reset(seed=s)`` is exactly ``AstrobeeTumbleEnv`` reset with ``seed=s + i`` (or the
    ``i``-th seed of a list; seeds follow the single environment's rule, integers in
    ``[0, 2**63)``, :func:`fkn_bench.inputs.check_seed`), including the episodes that follow through autoreset, which use
    Gymnasium's next-step mode: the step after a truncation ignores its actions and returns the
    first observation of the next episode with reward 0. All sub-environments share the
    scenario, so their episodes end together. ``info`` carries ``step``, ``episode_seed`` and,
    with ``expose_truth=True``, ``truth (N, 13)``, each with its ``_key`` mask.

    Autoreset: ``metadata["autoreset_mode"]`` is ``AutoresetMode.NEXT_STEP``, Gymnasium's
    default, so ``gym.make_vec(..., vectorization_mode="sync")`` (a ``SyncVectorEnv`` of single
    environments) gives the same outputs bit for bit, only slower; ``reset(options={"reset_mask":
    ...})`` is refused (the episodes end together).

    Speed: episode data are generated ``chunk_size`` steps at a time for all environments (see
    :data:`CHUNK_SAMPLES`), step-major, so that a step reads contiguous memory; the reward is
    computed on component rows (:func:`~fkn_bench.envs.rewards.estimate_cost_components`).
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int = 1,
        scenario: str | Scenario = "ds1",
        *,
        expose_truth: bool = False,
        reward_weights: Mapping[str, float] | None = None,
        render_mode: str | None = None,
        chunk_size: int | None = None,
        **overrides: Any,
    ) -> None:
        self.num_envs = num_envs = check_count(num_envs, "num_envs")
        if chunk_size is None:
            chunk_size = min(512, max(16, CHUNK_SAMPLES // num_envs))
        self._configure(scenario, expose_truth, reward_weights, render_mode, chunk_size, overrides)
        self.single_observation_space = observation_space(self.scenario.n_steps, self.scenario.dt)
        self.single_action_space = action_space()
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.observation_space["pose"] = pose_space(num_envs)  # a missing (NaN) pose stays a member
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._rngs: list[np.random.Generator] = []
        self._needs_autoreset = False
        self.episode_seeds = np.zeros(num_envs, dtype=np.int64)

    def _start_episodes(self, seeds: Sequence[int]) -> None:
        self.episode_seeds = np.asarray(seeds, dtype=np.int64)
        self._start(EpisodeStream(self.scenario, [int(s) for s in seeds]))

    def _load_chunk(self) -> None:
        """Load the next chunk step-major, so that each step reads contiguous memory: poses
        ``(n, N, 7)``, validity ``(n, N)`` and the truth component-major ``(n, 13, N)`` (each
        component of one step a contiguous row, as the reward reads it), with the truth's
        normalised quaternions ``(4, n, N)``."""
        self._chunk_start = self._stream.index
        self._times, self._truth_steps, self._pose_steps, valid = self._stream.advance(self._chunk_size, step_major=True)
        self._valid_steps = valid.astype(np.int64)
        self._unit_truth = unit_quaternions(self._truth_steps.transpose(1, 0, 2))

    def _observation(self) -> dict[str, Any]:
        i = self._index - self._chunk_start
        return {
            "pose": self._pose_steps[i].copy().view(MeasuredPose),
            "valid": self._valid_steps[i].copy(),
            "time": np.full(self.num_envs, self._times[i]),
        }

    def _info(self) -> dict[str, Any]:
        n = self.num_envs
        info: dict[str, Any] = {"step": np.full(n, self._index, dtype=np.int64)}
        info["episode_seed"] = self.episode_seeds.copy()
        if self.expose_truth:
            info["truth"] = self._truth_steps[self._index - self._chunk_start].T.copy()
        for key in list(info):  # Gymnasium's masks: every sub-environment has every key
            info[f"_{key}"] = np.ones(n, dtype=bool)
        return info

    # ------------------------------------------------------------------ Gymnasium API
    def reset(
        self, *, seed: int | Sequence[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        if options and "reset_mask" in options:
            raise NotImplementedError(
                "AstrobeeTumbleVectorEnv resets all sub-environments together (their episodes end together)"
            )
        seeds = self._reset_seeds(seed)
        super().reset(seed=seeds[0])
        if seed is not None or not self._rngs:
            self._rngs = [seeding.np_random(s)[0] for s in seeds]
        self._start_episodes([episode_seed_for_reset(s, rng) for s, rng in zip(seeds, self._rngs)])
        self._needs_autoreset = False
        return self._observation(), self._info()

    def _reset_seeds(self, seed: Any) -> list[int | None]:
        """The sub-environments' seeds of ``reset(seed=...)``: ``seed + i`` for an integer, the
        entries of a list, tuple or 1-d array of ``num_envs`` (None entries draw), or all None;
        each under :func:`fkn_bench.inputs.check_seed`'s rule, the single environment's
        (``ValueError`` naming the seed otherwise)."""
        n = self.num_envs
        if seed is None:
            return [None] * n
        if isinstance(seed, (list, tuple)) or (isinstance(seed, np.ndarray) and seed.ndim == 1):
            if len(seed) != n:
                raise ValueError(f"expected {n} seeds (got {len(seed)})")
            return [None if s is None else check_seed(s, f"seed[{i}]") for i, s in enumerate(seed)]
        first = check_seed(seed)  # anything else is refused here, as the single environment does
        check_seed(first + n - 1, f"seed + {n - 1} (the seed of sub-environment {n - 1})")
        return [first + i for i in range(n)]

    def step(self, actions: ArrayF) -> tuple[dict[str, Any], ArrayF, ArrayF, ArrayF, dict[str, Any]]:
        if self._stream is None:
            raise ResetNeeded("call reset() before step()")
        n = self.num_envs
        if self._needs_autoreset:
            self._start_episodes([episode_seed_for_reset(None, rng) for rng in self._rngs])
            self._needs_autoreset = False
            return self._observation(), np.zeros(n), np.zeros(n, dtype=bool), np.zeros(n, dtype=bool), self._info()
        rewards = self._rewards(actions)
        truncated = self._needs_autoreset = self._next_step()
        terminated = np.zeros(n, dtype=bool)
        return self._observation(), rewards, terminated, np.full(n, truncated), self._info()

    def _rewards(self, actions: ArrayF) -> ArrayF:
        """Rewards of ``actions (N, 13)`` at the current step, validated as
        :func:`~fkn_bench.envs.spaces.validate_actions` does (same errors). The usual float64
        ``(N, 13)`` array is checked through two reductions and the quaternion norms the reward
        computes anyway: an entry that is NaN or beyond ``+-ACTION_LIMIT`` (inf included) fails
        the first (NaN propagates through ``min`` and ``max``), a zero quaternion the second, and
        then the full validation names the entry. Within the limits every reward is finite."""
        n = self.num_envs
        if not (type(actions) is np.ndarray and actions.dtype == np.float64 and actions.shape == (n, 13)
                and actions.min() >= -ACTION_LIMIT and actions.max() <= ACTION_LIMIT):
            actions = validate_actions(actions, batch=n)
        estimate = np.ascontiguousarray(actions.T)
        i = self._index - self._chunk_start
        with np.errstate(all="ignore"):  # a zero quaternion's NaN is caught below, and named
            cost, norm2 = cost_and_quaternion_norm(self._truth_steps[i], estimate, self.reward_weights,
                                                   unit_truth=self._unit_truth[:, i])
        if not norm2.min() >= QUATERNION_NORM_MIN:
            validate_actions(actions, batch=n)  # raises, naming the entry
        return -cost
