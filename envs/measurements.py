"""Noisy pose measurements of a ground-truth trajectory: noise, schedule, dropout, gaps,
outliers and quaternion sign flips.

Random numbers come from independent streams keyed by ``(episode seed, stream name, block)``
where a block is :data:`BLOCK` consecutive steps (see :func:`stream`). Hence

* every effect has its own stream: a measurement that survives dropout has the value it would
  have had without dropout, and a sign flip changes nothing but the sign;
* any step range can be generated on its own (random access, e.g. only the test split), and
  generating in chunks of any size gives the same values as generating in one piece.

Noise model (FlexKalmanNet, section 4.1): position ``r + n`` with ``n ~ N(0, s_r^2 I3)``;
attitude ``exp(e / 2) (x) q`` with ``e ~ N(0, s_theta^2 I3)`` a world-frame error rotation.
Outliers replace the attitude by a uniformly random one and add ``N(0, s_out^2 I3)`` to the
position; a sign flip negates the measured quaternion.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fkn_bench.geometry import quaternion as quat
from fkn_bench.scenarios import Scenario
from fkn_bench.types import ArrayB, ArrayF

__all__ = ["STREAMS", "BLOCK", "stream", "MeasurementGenerator"]

STREAMS: tuple[str, ...] = (
    "attitude0",
    "position0",
    "position_noise",
    "attitude_noise",
    "dropout",
    "burst",
    "outlier",
    "outlier_attitude",
    "outlier_position",
    "sign_flip",
)
"""Names of the independent random streams of an episode. Their order fixes their keys: append
new streams at the end."""

BLOCK = 4096
"""Steps per random-stream block."""

# per-step draw shape and method of each measurement stream
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


def stream(seed: int, name: str, block: int = 0) -> np.random.Generator:
    """The random generator of stream ``name``, block ``block``, of episode ``seed`` (>= 0)."""
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
        raise ValueError(f"episode seed must be a non-negative integer (got {seed!r})")
    key = STREAMS.index(name)
    return np.random.default_rng(np.random.SeedSequence(entropy=int(seed), spawn_key=(key, int(block))))


class MeasurementGenerator:
    """Measurements for a batch of episodes over any step range.

    Args:
        scenario: noise, schedule and corruption settings.
        seeds: one episode seed per batch row.
    """

    def __init__(self, scenario: Scenario, seeds: Sequence[int]) -> None:
        self._scenario = scenario
        self._seeds = tuple(int(s) for s in seeds)
        self._cache: dict[str, tuple[int, ArrayF]] = {}
        sc = scenario
        self._active = ["position_noise", "attitude_noise"]
        if sc.dropout > 0:
            self._active.append("dropout")
        if sc.burst_length > 0 and sc.burst_rate > 0:
            self._active.append("burst")
        if sc.outlier_fraction > 0:
            self._active += ["outlier", "outlier_attitude", "outlier_position"]
        if sc.sign_flip_probability > 0:
            self._active.append("sign_flip")

    def _block(self, name: str, block: int) -> ArrayF:
        cached = self._cache.get(name)
        if cached is not None and cached[0] == block:
            return cached[1]
        method, shape = _DRAWS[name]
        out = np.empty((len(self._seeds), BLOCK, *shape))
        for row, seed in enumerate(self._seeds):
            getattr(stream(seed, name, block), method)(out=out[row])
        self._cache[name] = (block, out)
        return out

    def draws(self, name: str, start: int, stop: int) -> ArrayF:
        """Raw draws of stream ``name`` for global steps ``[start, stop)``: ``(B, n, ...)``."""
        method, shape = _DRAWS[name]
        parts = []
        first, last = start // BLOCK, (stop - 1) // BLOCK
        for block in range(first, last + 1):
            lo = max(start, block * BLOCK) - block * BLOCK
            hi = min(stop, (block + 1) * BLOCK) - block * BLOCK
            parts.append(self._block(name, block)[:, lo:hi])
        if not parts:
            return np.empty((len(self._seeds), 0, *shape))
        return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)

    def _burst_gaps(self, start: int, stop: int) -> ArrayB:
        """True where a burst gap covers the step (a gap started in the last ``L`` steps)."""
        sc = self._scenario
        lookback = max(0, start - sc.burst_length + 1)
        u = self.draws("burst", lookback, stop)
        steps = np.arange(lookback, stop)
        starts = np.where(u < sc.burst_rate, steps[None, :].astype(float), -np.inf)
        last_start = np.maximum.accumulate(starts, axis=1)[:, start - lookback :]
        return np.arange(start, stop)[None, :] - last_start < sc.burst_length

    def generate(self, truth_pose: ArrayF, start: int) -> tuple[ArrayF, ArrayB]:
        """Measurements of true poses ``truth_pose (B, n, 7)`` at global steps ``start ..``.

        Returns:
            ``(measurements, valid)``: ``(B, n, 7)`` with NaN rows where missing, and ``(B, n)``.
        """
        sc = self._scenario
        batch, n, _ = truth_pose.shape
        stop = start + n
        steps = np.arange(start, stop)

        out = np.empty((batch, n, 7))
        e = self.draws("attitude_noise", start, stop) * sc.sigma_attitude_effective
        out[..., :4] = quat.multiply(quat.from_rotation_vector(e), truth_pose[..., :4])
        np.multiply(self.draws("position_noise", start, stop), sc.sigma_position_effective, out=out[..., 4:])
        out[..., 4:] += truth_pose[..., 4:7]

        valid = np.empty((batch, n), dtype=bool)
        valid[:] = steps % sc.measurement_every == 0
        if "dropout" in self._active:
            valid &= self.draws("dropout", start, stop) >= sc.dropout
        if "burst" in self._active:
            valid &= ~self._burst_gaps(start, stop)
        if "outlier" in self._active:
            is_outlier = valid & (self.draws("outlier", start, stop) < sc.outlier_fraction)
            random_q = self.draws("outlier_attitude", start, stop)
            random_q = random_q / np.linalg.norm(random_q, axis=-1, keepdims=True)
            offset = sc.outlier_position_sigma * self.draws("outlier_position", start, stop)
            out[..., :4] = np.where(is_outlier[..., None], random_q, out[..., :4])
            out[..., 4:] += np.where(is_outlier[..., None], offset, 0.0)
        if "sign_flip" in self._active:
            flip = self.draws("sign_flip", start, stop) < sc.sign_flip_probability
            out[..., :4] *= np.where(flip, -1.0, 1.0)[..., None]
        out[~valid] = np.nan
        return out, valid
