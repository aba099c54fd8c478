"""Noisy pose measurements of a ground-truth trajectory: noise, schedule, dropout, gaps,
outliers and quaternion sign flips.

Random numbers come from independent streams keyed by ``(episode seed, stream name, block)``
where a block is :data:`BLOCK` consecutive steps (see :func:`stream`). The position and attitude
noise streams hold one draw per *scheduled* measurement step (``k % measurement_every == 0``),
the others one draw per step. Hence

* every effect has its own stream: a measurement that survives dropout has the value it would
  have had without dropout, and a sign flip changes nothing but the sign;
* any step range can be generated on its own (random access, e.g. only the test split), and
  generating in chunks of any size gives the same values as generating in one piece;
* scenarios with the same measurement schedule see the same noise draws for the same seed
  (common random numbers), whatever their noise scale, dropout, outliers or sign flips.

Noise model (FlexKalmanNet, section 4.1): position ``r + n`` with ``n ~ N(0, s_r^2 I3)``;
attitude ``exp(e / 2) (x) q`` with ``e ~ N(0, s_theta^2 I3)`` a world-frame error rotation; both
standard deviations times :meth:`~fkn_bench.scenarios.Scenario.noise_factor` of the step (the
scenario's noise step, 1 by default).
Outliers replace the attitude by a uniformly random one and add ``N(0, s_out^2 I3)`` to the
position; a sign flip negates the measured quaternion.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fkn_bench.geometry import quaternion as quat
from fkn_bench.inputs import check_seed
from fkn_bench.scenarios import Scenario
from fkn_bench.types import ArrayB, ArrayF

__all__ = ["STREAMS", "BLOCK", "stream", "MeasurementGenerator"]

_SCHEDULED = ("position_noise", "attitude_noise")
_DRAWS: dict[str, tuple[str, tuple[int, ...]]] = {
    "position_noise": ("standard_normal", (3,)),
    "attitude_noise": ("standard_normal", (3,)),
    "dropout": ("random", ()),
    "burst": ("random", ()),
    "outlier": ("random", ()),
    "outlier_attitude": ("standard_normal", (4,)),
    "outlier_position": ("standard_normal", (3,)),
    "sign_flip": ("random", ()),
}
"""Per-step draw method and shape of each measurement stream."""

STREAMS: tuple[str, ...] = ("attitude0", "position0", *_DRAWS, "inertia", "kick", "kick_noise", "omega0", "velocity0")
"""Names of the independent random streams of an episode. Their order fixes their keys: append
new streams at the end (``kick`` and ``kick_noise``: the torque bursts of
:func:`fkn_bench.envs.episodes.rate_offsets`, one draw per step; ``omega0`` and ``velocity0``:
the scenario's prior over the initial rate and velocity, :func:`fkn_bench.envs.episodes.initial_rates`
and :func:`~fkn_bench.envs.episodes.initial_states`)."""

BLOCK = 4096
"""Steps per random-stream block."""


def stream(seed: int, name: str, block: int = 0) -> np.random.Generator:
    """The random generator of stream ``name``, block ``block``, of episode ``seed`` (an integer
    in ``[0, 2**63)``, :func:`fkn_bench.inputs.check_seed`)."""
    key = STREAMS.index(name)
    return np.random.default_rng(np.random.SeedSequence(entropy=check_seed(seed, "episode seed"), spawn_key=(key, int(block))))


class MeasurementGenerator:
    """Measurements for a batch of episodes (one seed per batch row) over any step range."""

    def __init__(self, scenario: Scenario, seeds: Sequence[int]) -> None:
        self._scenario = scenario
        self._seeds = tuple(int(s) for s in seeds)
        self._cache: dict[str, tuple[int, ArrayF]] = {}

    def _block_steps(self, name: str, block: int) -> ArrayF:
        """Global steps that own one draw each in ``block`` of stream ``name``."""
        lo, hi = block * BLOCK, (block + 1) * BLOCK
        if name in _SCHEDULED:
            k = self._scenario.measurement_every
            return np.arange(-(-lo // k) * k, hi, k)
        return np.arange(lo, hi)

    def _block(self, name: str, block: int) -> ArrayF:
        cached = self._cache.get(name)
        if cached is not None and cached[0] == block:
            return cached[1]
        method, shape = _DRAWS[name]
        count = len(self._block_steps(name, block))
        out = np.empty((len(self._seeds), count, *shape))
        for row, seed in enumerate(self._seeds):
            getattr(stream(seed, name, block), method)(out=out[row])
        self._cache[name] = (block, out)
        return out

    def draws(self, name: str, steps: ArrayF) -> ArrayF:
        """Draws of stream ``name`` for the sorted global ``steps`` (which must own draws:
        scheduled steps for the noise streams): ``(B, len(steps), ...)``."""
        _, shape = _DRAWS[name]
        if len(steps) == 0:
            return np.empty((len(self._seeds), 0, *shape))
        parts = []
        blocks = steps // BLOCK
        for block in range(int(blocks[0]), int(blocks[-1]) + 1):
            wanted = steps[blocks == block]
            if len(wanted) == 0:
                continue
            owners = self._block_steps(name, block)
            index = np.searchsorted(owners, wanted)
            parts.append(self._block(name, block)[:, index])
        return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)

    def _burst_gaps(self, start: int, stop: int) -> ArrayB:
        """True where a burst gap covers the step (a gap started in the last ``L`` steps)."""
        sc = self._scenario
        lookback = max(0, start - sc.burst_length + 1)
        steps = np.arange(lookback, stop)
        u = self.draws("burst", steps)
        starts = np.where(u < sc.burst_rate, steps[None, :].astype(float), -np.inf)
        last_start = np.maximum.accumulate(starts, axis=1)[:, start - lookback :]
        return np.arange(start, stop)[None, :] - last_start < sc.burst_length

    def generate(self, truth_pose: ArrayF, start: int, *, step_major: bool = False) -> tuple[ArrayF, ArrayB]:
        """Measurements of true poses at global steps ``start ..``, component-major.

        Args:
            truth_pose: ``(B, 7, n)`` true ``[q, r]`` of the next ``n`` steps (``step_major``:
                ``(n, 7, B)``).
            start: global step index of the first of them.
            step_major: the layout of ``truth_pose`` and of the measurements returned.

        Returns:
            ``(measurements, valid)``: ``(B, 7, n)`` with NaN where missing, and ``(B, n)``
            (``step_major``: ``(n, B, 7)`` and ``(n, B)``; the same values).
        """
        sc = self._scenario
        if step_major:
            n, _, batch = truth_pose.shape
        else:
            batch, _, n = truth_pose.shape
        stop = start + n
        steps = np.arange(start, stop)
        scheduled = steps[steps % sc.measurement_every == 0]
        columns = scheduled - start
        valid = np.zeros((batch, n), dtype=bool)
        valid[:, columns] = True
        if sc.dropout > 0:
            valid &= self.draws("dropout", steps) >= sc.dropout
        if sc.burst_length > 0 and sc.burst_rate > 0:
            valid &= ~self._burst_gaps(start, stop)

        # noisy poses at the scheduled steps only: (B, m, 7)
        truth_at = truth_pose[columns].transpose(2, 0, 1) if step_major else truth_pose[:, :, columns].transpose(0, 2, 1)
        pose = np.empty((batch, len(columns), 7))
        factor = sc.noise_factor(scheduled)[None, :, None]  # the noise step (1 unless configured)
        e = self.draws("attitude_noise", scheduled)
        e *= sc.sigma_attitude_effective
        if sc.noise_step_scale != 1.0:
            e *= factor
        quat.multiply(quat.from_rotation_vector(e), truth_at[..., :4], out=pose[..., :4])
        r = self.draws("position_noise", scheduled)
        r *= sc.sigma_position_effective
        if sc.noise_step_scale != 1.0:
            r *= factor
        np.add(truth_at[..., 4:7], r, out=pose[..., 4:])
        if sc.outlier_fraction > 0:
            is_outlier = valid[:, columns] & (self.draws("outlier", scheduled) < sc.outlier_fraction)
            random_q = self.draws("outlier_attitude", scheduled)
            random_q /= np.linalg.norm(random_q, axis=-1, keepdims=True)
            offset = sc.outlier_position_sigma * self.draws("outlier_position", scheduled)
            pose[..., :4] = np.where(is_outlier[..., None], random_q, pose[..., :4])
            pose[..., 4:] += np.where(is_outlier[..., None], offset, 0.0)
        if sc.sign_flip_probability > 0:
            flip = self.draws("sign_flip", scheduled) < sc.sign_flip_probability
            pose[..., :4] *= np.where(flip, -1.0, 1.0)[..., None]

        kept = np.where(valid[:, columns, None], pose, np.nan)
        if step_major:
            out = np.full((n, batch, 7), np.nan)
            out[columns] = kept.transpose(1, 0, 2)
            return out, np.ascontiguousarray(valid.T)
        out = np.full((batch, 7, n), np.nan)
        out[:, :, columns] = kept.transpose(0, 2, 1)
        return out, valid
