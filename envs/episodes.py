"""Episodes: ground truth plus measurements of a scenario for a batch of seeds.

:func:`generate_episodes` returns whole episodes (or one split of them) as numpy arrays, batch
first; :class:`EpisodeStream` yields the same data chunk by chunk for the environments. Both give
identical values for the same scenario and seeds, whatever the chunk sizes or batch composition.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fkn_bench.envs.dynamics import ForcedRotation, FreeTumble, PerturbedRotation
from fkn_bench.envs.measurements import BLOCK, MeasurementGenerator, stream
from fkn_bench.geometry import quaternion as quat
from fkn_bench.inputs import check_seed, describe
from fkn_bench.limits import check_memory
from fkn_bench.scenarios import SPLITS, Scenario, get_scenario
from fkn_bench.types import ArrayB, ArrayF, Bool, Float

__all__ = ["Episodes", "EpisodeStream", "generate_episodes", "initial_rates", "initial_states", "rate_offsets",
           "true_inertia"]


@dataclass(frozen=True, eq=False)
class Episodes:
    """A batch of episode segments (all the same length), batch first: one object for all the
    sequences, whose arrays have the sequence axis first; ``episodes[i]`` is sequence ``i`` as an
    :class:`Episodes` of one (``len(episodes)`` sequences).

    Attributes:
        scenario: the generating configuration.
        seeds: episode seed of each batch row, ``(B,)``.
        start: global step index of the first sample (0, or the start of a split).
        times: sample times ``(T,)``, s, counted from the episode start.
        truth: true states ``(B, T, 13)``.
        measurements: measured poses ``(B, T, 7)``, NaN where missing.
        valid: measurement validity ``(B, T)``.
        measurement_covariances: the covariance each measurement states of its own error,
            ``(B, T, 6, 6)`` in the error order ``[dtheta (rad), dr (m)]`` (world-frame attitude
            error, ``fkn_bench/DESIGN.md``), NaN where a measurement states none; None when no
            measurement does (a recording's ``PoseWithCovarianceStamped`` topic, or a scenario
            with ``measurement_covariance = True``, carry them).
    """

    scenario: Scenario
    seeds: tuple[int, ...]
    start: int
    times: Float[ArrayF, "T"]
    truth: Float[ArrayF, "B T 13"]
    measurements: Float[ArrayF, "B T 7"]
    valid: Bool[ArrayB, "B T"]
    measurement_covariances: Float[ArrayF, "B T 6 6"] | None = None

    @property
    def batch_size(self) -> int:
        return self.truth.shape[0]

    @property
    def n_steps(self) -> int:
        return self.truth.shape[1]

    def __len__(self) -> int:
        """The number of sequences (the batch size)."""
        return self.batch_size

    def __getitem__(self, index: int | slice) -> Episodes:
        """Sequence ``index`` (an :class:`Episodes` of one, still batch first: ``truth`` is
        ``(1, T, 13)``) or a slice of the sequences; the arrays are views."""
        if isinstance(index, slice):
            rows = range(self.batch_size)[index]
            picked: slice = index
        elif isinstance(index, (int, np.integer)) and not isinstance(index, bool):
            position = int(index) + (self.batch_size if index < 0 else 0)
            if not 0 <= position < self.batch_size:
                raise IndexError(f"sequence {index} out of range: these episodes hold {self.batch_size}")
            rows, picked = range(position, position + 1), slice(position, position + 1)
        else:
            raise TypeError(f"episodes are indexed by an integer or a slice of sequences (got {index!r})")
        return Episodes(
            scenario=self.scenario,
            seeds=tuple(self.seeds[i] for i in rows),
            start=self.start,
            times=self.times,
            truth=self.truth[picked],
            measurements=self.measurements[picked],
            valid=self.valid[picked],
            measurement_covariances=None if self.measurement_covariances is None else self.measurement_covariances[picked],
        )

    def window(self, start: int, stop: int) -> Episodes:
        """Steps ``[start, stop)`` relative to this segment."""
        return Episodes(
            scenario=self.scenario,
            seeds=self.seeds,
            start=self.start + start,
            times=self.times[start:stop],
            truth=self.truth[:, start:stop],
            measurements=self.measurements[:, start:stop],
            valid=self.valid[:, start:stop],
            measurement_covariances=(None if self.measurement_covariances is None
                                     else self.measurement_covariances[:, start:stop]),
        )

    def split(self, name: str) -> Episodes:
        """The named split (``train``, ``val``, ``test`` or ``full``) of full-length episodes."""
        if self.start != 0 or self.n_steps != self.scenario.n_steps:
            raise ValueError("split() needs full-length episodes (generate with split='full')")
        if self.scenario.split_mode == "episodes" and name in ("train", "val"):
            raise ValueError(f"scenario '{self.scenario.name}' splits by episodes: its {name} split is other "
                             f"episodes (generate_episodes(scenario, n, split={name!r})), not a piece of these")
        return self.window(*_split_bounds(self.scenario, name))


def _split_bounds(scenario: Scenario, name: str) -> tuple[int, int]:
    if name not in SPLITS:
        raise ValueError(f"unknown split {name!r}; valid splits: {', '.join(SPLITS)}")
    return scenario.split_bounds()[name]


def initial_states(scenario: Scenario, seeds: Sequence[int]
                   ) -> tuple[Float[ArrayF, "B 4"], Float[ArrayF, "B 3"], Float[ArrayF, "B 3"]]:
    """Initial attitude ``(B, 4)``, position ``(B, 3)`` and velocity ``(B, 3)`` per seed."""
    attitudes, positions = [], []
    for seed in seeds:
        q_rng = stream(seed, "attitude0")
        attitudes.append(
            np.array(scenario.attitude0) if scenario.attitude0 is not None else quat.random_uniform(q_rng)
        )
        offset = stream(seed, "position0").standard_normal(3)
        positions.append(np.array(scenario.position0) + scenario.position0_std * offset)
    velocity = np.tile(np.array(scenario.velocity0), (len(seeds), 1))
    if scenario.velocity0_std:  # (no draw at zero spread: the velocity stays exactly velocity0)
        velocity += scenario.velocity0_std * np.array([stream(seed, "velocity0").standard_normal(3) for seed in seeds])
    return np.array(attitudes).reshape(-1, 4), np.array(positions).reshape(-1, 3), velocity.reshape(-1, 3)


def initial_rates(scenario: Scenario, seeds: Sequence[int]) -> Float[ArrayF, "B 3"]:
    """Each seed's initial angular rate ``(B, 3)``, rad/s, in the scenario's ``omega0_frame``:
    ``omega0`` for every seed, or, with a rate prior (:class:`~fkn_bench.scenarios.Scenario`,
    "Prior"), ``m u`` with the axis ``u`` (uniform on the sphere: a normalised standard normal
    3-vector, drawn first) and the magnitude ``m`` (log-uniform: ``exp(U(log low, log high))``;
    or uniform) from the seed's ``omega0`` stream."""
    base = np.array(scenario.omega0, dtype=float)
    if not scenario.has_rate_prior:
        return np.tile(base, (len(seeds), 1))

    def norm(v: ArrayF) -> float:  # element-wise and libm: the same bits on every CPU (no BLAS dot)
        return math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])

    out = np.empty((len(seeds), 3))
    for row, seed in enumerate(seeds):
        rng = stream(seed, "omega0")
        axis = rng.standard_normal(3) if scenario.omega0_axis == "uniform" else base
        axis = axis / norm(axis)
        if scenario.omega0_magnitude is None:
            magnitude = norm(base)
        elif scenario.omega0_magnitude_distribution == "log-uniform":
            low, high = scenario.omega0_magnitude
            magnitude = math.exp(rng.uniform(math.log(low), math.log(high)))
        else:
            magnitude = float(rng.uniform(*scenario.omega0_magnitude))
        out[row] = magnitude * axis
    return out


def true_inertia(scenario: Scenario, seeds: Sequence[int]) -> Float[ArrayF, "B 3"]:
    """The true principal moments ``(B, 3)`` (kg m^2) of each seed's body: the scenario's
    ``inertia`` scaled per axis by ``1 + u``, ``u ~ U(-inertia_error, inertia_error)``."""
    nominal = np.array(scenario.inertia)
    if scenario.inertia_error == 0.0:
        return np.tile(nominal, (len(seeds), 1))
    error = scenario.inertia_error
    return np.array([nominal * (1.0 + stream(seed, "inertia").uniform(-error, error, 3)) for seed in seeds])


def kick_bursts(scenario: Scenario, seeds: Sequence[int]) -> tuple[Bool[ArrayB, "B N"], Float[ArrayF, "B N 3"]]:
    """Where each seed's unmodelled torque bursts act, ``(B, N)`` (True at the steps of a burst;
    ``N = n_steps``), and the standard-normal draws ``n_k (B, N, 3)`` of their rate steps (see
    :func:`rate_offsets`): a burst of ``kick_length`` steps starts at step ``k`` where the
    ``kick`` stream's uniform draw is below ``kick_rate``. All False (and zeros) without bursts."""
    sc, steps = scenario, scenario.n_steps
    inside, noise = np.zeros((len(seeds), steps), dtype=bool), np.zeros((len(seeds), steps, 3))
    if not sc.has_kicks:
        return inside, noise
    blocks = range(-(-steps // BLOCK))
    for row, seed in enumerate(seeds):
        starts = np.concatenate([stream(seed, "kick", b).random(BLOCK) for b in blocks])[:steps] < sc.kick_rate
        noise[row] = np.concatenate([stream(seed, "kick_noise", b).standard_normal((BLOCK, 3)) for b in blocks])[:steps]
        # in a burst: a start in the last kick_length steps (this one included)
        started = np.cumsum(starts)
        before = np.concatenate([np.zeros(sc.kick_length, dtype=started.dtype), started[:-sc.kick_length]])[:steps]
        inside[row] = started - before > 0
    return inside, noise


def rate_offsets(scenario: Scenario, seeds: Sequence[int]) -> Float[ArrayF, "B N 3"]:
    """The world-frame rate offsets ``d (B, N, 3)`` (rad/s) of the unmodelled torque bursts of
    each seed's whole episode (``N = n_steps``; zero without bursts; see :class:`Scenario`):
    during a burst (:func:`kick_bursts`) ``d`` takes the step ``kick_sigma n_k`` (``n_k`` from
    the ``kick_noise`` stream) and it decays by ``exp(-dt / kick_decay)`` at every step."""
    from scipy.signal import lfilter  # here, not at module level: a slow import (DESIGN.md, "Performance notes")

    sc = scenario
    out = np.zeros((len(seeds), sc.n_steps, 3))
    if not sc.has_kicks:
        return out
    inside, noise = kick_bursts(sc, seeds)
    decay = float(np.exp(-sc.dt / sc.kick_decay))
    increments = np.where(inside[..., None], sc.kick_sigma * noise, 0.0)
    return lfilter([1.0], [1.0, -decay], increments, axis=1)  # d_k = a d_{k-1} + u_k


GENERATION_BYTES_PER_STEP = 400
"""Bytes that generating one step of one episode takes at its peak (truth ``(13,)``, measurement
``(7,)`` and validity in float64, plus the generators' temporaries), for
:func:`fkn_bench.limits.check_memory`; the measured peak: ``fkn_bench/DESIGN.md``, "Performance
notes"."""


class EpisodeStream:
    """Generates a batch of episodes of ``scenario``, one per non-negative integer seed, chunk by
    chunk (``advance(n)``), for the environments."""

    def __init__(self, scenario: Scenario, seeds: Sequence[int]) -> None:
        self.scenario = scenario
        self.seeds = tuple(check_seed(s, f"seeds[{i}]") for i, s in enumerate(seeds))
        self._q0, self._r0, self._v0 = initial_states(scenario, self.seeds)
        self._rotation = self._make_rotation()
        self._measurements = MeasurementGenerator(scenario, self.seeds)
        self.index = 0

    def _make_rotation(self) -> ForcedRotation | PerturbedRotation | FreeTumble:
        sc = self.scenario
        omega = initial_rates(sc, self.seeds)
        if sc.omega0_frame == "body":
            omega = quat.rotate(self._q0, omega)
        if sc.dynamics == "forced" and sc.has_kicks:
            return PerturbedRotation(self._q0, omega, rate_offsets(sc, self.seeds), sc.dt)
        if sc.dynamics == "forced":
            return ForcedRotation(self._q0, omega, sc.dt)
        return FreeTumble(self._q0, omega, true_inertia(sc, self.seeds), sc.dt, sc.free_substeps)

    def seek(self, index: int) -> None:
        """Continue from step ``index``: O(1) for forced rotation; free tumbling integrates
        forward from the current step (or from the start when seeking backwards)."""
        index = int(index)
        if not 0 <= index <= self.scenario.n_steps:
            raise ValueError(f"step index must be in [0, {self.scenario.n_steps}] (got {index})")
        if isinstance(self._rotation, (ForcedRotation, PerturbedRotation)):
            self._rotation.seek(index)
        else:
            if index < self.index:
                self._rotation = self._make_rotation()
                self.index = 0
            while self.index < index:
                n = min(4096, index - self.index)
                self._rotation.advance(n)
                self.index += n
        self.index = index

    def advance(self, n: int, *, step_major: bool = False) -> tuple[ArrayF, ArrayF, ArrayF, ArrayB]:
        """The next ``n`` steps (clipped at the episode end).

        Returns:
            ``(times (n,), truth (B, n, 13), measurements (B, n, 7), valid (B, n))``; the two
            state arrays are views of component-major buffers (not C-contiguous). With
            ``step_major`` (the vector environment's layout: each step's data contiguous), the
            same values as ``truth (n, 13, B)`` (each component of a step a contiguous row),
            ``measurements (n, B, 7)`` and ``valid (n, B)``, all C-contiguous.
        """
        n = max(0, min(int(n), self.scenario.n_steps - self.index))
        check_memory(len(self.seeds) * n * GENERATION_BYTES_PER_STEP,
                     f"generating {len(self.seeds)} episode(s) of {n} steps of scenario {self.scenario.name}",
                     "fewer seeds or a scenario with fewer steps (n_steps)")
        times = np.arange(self.index, self.index + n) * self.scenario.dt
        q, omega = self._rotation.advance(n, step_major=step_major)
        if step_major:  # (n, 13, B)
            truth = np.empty((n, 13, len(self.seeds)))
            truth[:, 0:4] = q
            v0, r0 = np.ascontiguousarray(self._v0.T), np.ascontiguousarray(self._r0.T)
            np.multiply(v0[None], times[:, None, None], out=truth[:, 4:7])
            truth[:, 4:7] += r0[None]
            truth[:, 7:10] = omega
            truth[:, 10:13] = v0[None]
            measurements, valid = self._measurements.generate(truth[:, :7], self.index, step_major=True)
            self.index += n
            return times, truth, measurements, valid
        # component-major buffer (B, 13, n): long inner loops; returned as a (B, n, 13) view
        truth = np.empty((len(self.seeds), 13, n))
        truth[:, 0:4] = q
        np.multiply(self._v0[:, :, None], times[None, None, :], out=truth[:, 4:7])
        truth[:, 4:7] += self._r0[:, :, None]
        truth[:, 7:10] = omega
        truth[:, 10:13] = self._v0[:, :, None]
        measurements, valid = self._measurements.generate(truth[:, :7], self.index)
        self.index += n
        return times, truth.transpose(0, 2, 1), measurements.transpose(0, 2, 1), valid


def generate_episodes(
    scenario: str | Scenario, seeds: int | Sequence[int], *, split: str = "full"
) -> Episodes:
    """:class:`Episodes` (batch axis first) of ``scenario`` (a registered name or a
    :class:`Scenario`) for ``seeds`` (an int ``N`` means seeds ``0 .. N-1``; else a list of
    seeds, each an integer in ``[0, 2**63)``, :func:`fkn_bench.inputs.check_seed`), whole or one
    ``split`` (``full``, ``train``, ``val`` or ``test``). For an episode-split scenario
    (``split_mode = "episodes"``) a split is whole episodes and ``seeds`` index the split's own
    pool: the returned ``seeds`` are the episode seeds, :meth:`Scenario.split_seeds`."""
    scenario = get_scenario(scenario)
    start, stop = _split_bounds(scenario, split)
    if isinstance(seeds, (int, np.integer)) and not isinstance(seeds, (bool, np.bool_)):
        seed_list = list(range(seeds))
    elif isinstance(seeds, (str, bytes, bool, np.bool_)) or not hasattr(seeds, "__iter__") or (isinstance(seeds, np.ndarray) and seeds.ndim == 0):
        raise ValueError(f"seeds must be a number of episodes or a list of seeds (got {describe(seeds)})")
    else:
        seed_list = [check_seed(s, f"seeds[{i}]") for i, s in enumerate(seeds)]
    if not seed_list:
        raise ValueError("at least one seed is required")
    seed_list = scenario.split_seeds(split, seed_list)  # episode-split scenarios: the split's own pool
    source = EpisodeStream(scenario, seed_list)
    source.seek(start)
    times, truth, measurements, valid = source.advance(stop - start)
    truth, measurements = np.ascontiguousarray(truth), np.ascontiguousarray(measurements)
    covariances = measurement_covariances(scenario, start, valid) if scenario.measurement_covariance else None
    return Episodes(scenario, tuple(seed_list), start, times, truth, measurements, valid, covariances)


def measurement_covariances(scenario: Scenario, start: int, valid: Bool[ArrayB, "B T"]) -> Float[ArrayF, "B T 6 6"]:
    """The covariance each measurement of steps ``start ..`` states (``measurement_covariance =
    True``, :class:`~fkn_bench.scenarios.Scenario`): ``diag(s_att^2 I3, s_pos^2 I3)`` with the
    standard deviations in force at its step, NaN where there is no measurement."""
    batch, steps = valid.shape
    factor = scenario.noise_factor(np.arange(start, start + steps)) ** 2
    variances = np.array([scenario.sigma_attitude_effective**2] * 3 + [scenario.sigma_position_effective**2] * 3)
    out = np.zeros((batch, steps, 6, 6))
    index = np.arange(6)
    out[:, :, index, index] = factor[None, :, None] * variances
    out[~valid] = np.nan
    return out
