"""The :class:`Scenario` configuration: dynamics, measurement model, schedule and splits.

A scenario is a complete, immutable description of how episodes are generated. It knows nothing
about estimators or scoring. Field values are SI units (rad, rad/s, m, m/s, s, kg m^2).

Seed policy (common random numbers): the episode for integer ``seed`` is drawn from independent
random streams keyed by ``(seed, stream name)`` only, never by the scenario. Two scenarios that
differ only in, say, noise scale or dropout therefore share the same ground truth and the same
standard-normal noise draws for the same seed; enabling sign flips changes nothing but signs.
The paper's single recording is ``dataset_seed`` (0): its train and validation splits are used for
training, and the test split of seeds ``0 .. N-1`` for evaluation.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ["Scenario", "ConfigError", "ASTROBEE_INERTIA", "ASTROBEE_MASS", "SPLITS", "MAX_RATE", "SEED_POOLS",
           "POOL_SIZE", "PRIOR_EPISODES"]

ASTROBEE_INERTIA: tuple[float, float, float] = (0.153428, 0.142714, 0.162303)
"""Astrobee flight GNC principal moments of inertia, kg m^2 (nasa/astrobee,
``astrobee/config/worlds/iss.config``)."""
ASTROBEE_MASS = 9.5838
"""Astrobee flight GNC mass, kg (same source)."""

SPLITS: tuple[str, ...] = ("train", "val", "test", "full")

POOL_SIZE = 2**61
"""Episodes per split of an episode-split scenario (``split_mode = "episodes"``)."""
PRIOR_EPISODES = 32
"""The fewest episodes of each pool (train, val) that fit anything to an episode-split scenario:
the training data of its learned filters (:mod:`fkn_bench.training.data`: 96 windows of 800 samples
from 300 s episodes, validated on 32 more) and the oracle EKF's noise, where the paper's protocol
has one recording of one fixed truth."""

SEED_POOLS: dict[str, int] = {"test": 0, "full": 0, "train": 2**62, "val": 2**62 + POOL_SIZE}
"""First episode seed of each split's pool in an episode-split scenario: episode ``i`` of split
``s`` is the episode of seed ``SEED_POOLS[s] + i``. Test (and full) episodes are seeds
``[0, 2**62)``, so that a leaderboard's seed ``s`` and ``reset(seed=s)`` are test episode ``s``;
training and validation episodes come from the disjoint ranges ``[2**62, 2**62 + 2**61)`` and
``[2**62 + 2**61, 2**63)``. Every episode seed keys its own random streams
(:func:`fkn_bench.envs.measurements.stream`, a ``numpy.random.SeedSequence`` of the seed), so the
pools are independent streams and no test truth is ever a training truth."""


class ConfigError(ValueError):
    """An invalid configuration value; the message names the field and its allowed range."""


def _check(condition: bool, name: str, allowed: str, value: Any) -> None:
    if not condition:
        raise ConfigError(f"scenario field '{name}' must be {allowed} (got {value!r})")


def _is_finite_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _vector(value: Any, name: str, length: int) -> tuple[float, ...]:
    try:
        items = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        items = ()
    ok = len(items) == length and all(map(math.isfinite, items))
    _check(ok, name, f"a sequence of {length} finite numbers", value)
    return items


MAX_NOISE = 1e6
"""The largest standard deviation a scenario's noise may have (m or rad, after ``noise_scale``):
larger noise is no measurement of this problem, and 1e300 overflows to NaN poses."""

MAX_RATE = 100.0
"""The largest initial angular rate a scenario may state, rad/s per axis and for a drawn magnitude
(16 revolutions per second, far beyond any free-flyer; the truth checks of recordings and datasets
allow 1e3)."""


@dataclass(frozen=True)
class Scenario:
    """A named, validated episode configuration.

    Dynamics
        ``dynamics``: ``"forced"`` keeps the world-frame angular velocity constant at ``omega0``
        (the paper's thruster-forced rotation; attitude by the exact quaternion exponential) and
        ``"free"`` integrates the torque-free rigid body with principal moments ``inertia``
        (Euler's equations and quaternion kinematics, RK4 with ``free_substeps`` sub-steps per
        sample), starting from rate ``omega0`` (rad/s) given in the world frame or, with
        ``omega0_frame = "body"``, in the body frame (so that, from a random attitude, the body
        spins about a chosen body axis). Unmodelled torque bursts (forced dynamics only): a burst
        of ``kick_length`` steps starts at any step with probability ``kick_rate``; during it the
        world-frame rate takes a random-walk step ``N(0, kick_sigma^2 I3)`` (rad/s) per step, and
        the accumulated offset decays back towards ``omega0`` with time constant ``kick_decay``
        (s; the rate controller of the forced rotation restoring it): ``d_k = exp(-dt /
        kick_decay) d_{k-1} + kick_sigma n_k [k in a burst]``, ``omega_k = omega0 + d_k``. ``inertia_error``: each seed's true principal moments
        are ``inertia * (1 + u)`` with ``u`` uniform in ``[-inertia_error, inertia_error]`` per
        axis (free dynamics only): ``inertia`` is then the nominal value an estimator is told.
        ``attitude0``: initial attitude (wxyz); ``None`` draws a uniformly random one per seed.
        ``position0`` (m) plus per-axis Gaussian spread ``position0_std`` and ``velocity0`` (m/s)
        plus per-axis Gaussian spread ``velocity0_std`` give the translation.
    Prior over the initial rate
        Each episode's initial rate is ``m u`` (rad/s, in ``omega0_frame``): the axis ``u`` is
        ``omega0``'s direction (``omega0_axis = "fixed"``) or uniform on the sphere
        (``"uniform"``), and the magnitude ``m`` is ``|omega0|`` or, with ``omega0_magnitude =
        (low, high)``, drawn log-uniformly (``omega0_magnitude_distribution``; or uniformly) in
        that range. With neither (the defaults) every episode spins at ``omega0``. Together with
        ``attitude0 = None``, ``position0_std``, ``velocity0_std`` and ``inertia_error`` this is
        the scenario's stated prior over its truth (:meth:`describe_prior`); every draw comes from
        the episode seed's own streams (``omega0``, ``velocity0``, ``position0``, ``attitude0``,
        ``inertia``), so an episode is the same whatever else the scenario changes, and a prior
        of zero spread draws nothing.
    Sampling
        ``dt`` (s) between samples, ``n_steps`` samples per episode. ``split_mode = "time"`` (the
        paper's): train, val and test are contiguous pieces of each episode, of fractions
        ``split`` in that order. ``split_mode = "episodes"`` (the prior families): every split is
        whole episodes, drawn from disjoint seed pools (:data:`SEED_POOLS`), so that no truth
        trained or validated on is ever tested on; ``split`` is then unused.
    Measurements
        Position noise N(0, (``noise_scale`` * ``sigma_position``)^2) per axis (m); attitude
        noise as an error rotation ``exp(e/2) (x) q`` with e ~ N(0, (``noise_scale`` *
        ``sigma_attitude``)^2 I3) (rad). A measurement exists at steps ``k`` with
        ``k % measurement_every == 0``, is then dropped with probability ``dropout``, and runs of
        ``burst_length`` missing steps start at any step with probability ``burst_rate``.
        A fraction ``outlier_fraction`` of the surviving measurements is replaced by gross errors
        (uniformly random attitude, position offset N(0, ``outlier_position_sigma``^2) per axis)
        and each measured quaternion is negated with probability ``sign_flip_probability``.
        With ``measurement_covariance`` each measurement also states its noise covariance, as a
        ``PoseWithCovarianceStamped`` would: ``diag(s_att^2 I3, s_pos^2 I3)`` with the standard
        deviations in force at its step (the noise step included; outliers state the nominal
        noise, as a sensor that does not know it failed would), in the error order ``[dtheta,
        dr]`` (:attr:`fkn_bench.envs.Episodes.measurement_covariances`).
        ``noise_step_scale`` multiplies both noise standard deviations in the middle third of
        each split (steps ``[a + (b - a) // 3, a + 2 (b - a) // 3)`` of each split ``[a, b)`` of
        train, val and test: every sequence trained on or evaluated is calm, noisy, calm; see
        :meth:`noise_factor`).
    Bookkeeping
        ``dataset_seed`` is the seed of the training data set; ``test_episodes`` the number of
        test episodes (seeds ``0 .. test_episodes - 1``) ``fkn-bench run`` scores without
        ``--seeds`` (not part of the configuration hash: it generates nothing); ``model_family`` names the
        committed learned model that applies to this scenario (``"ds1"`` or ``"ds2"`` for the
        constant rates, ``"tumble"`` for free tumbling).
    """

    name: str
    description: str = ""
    dynamics: Literal["forced", "free"] = "forced"
    omega0: tuple[float, float, float] = (0.02, 0.04, 0.06)
    omega0_frame: Literal["world", "body"] = "world"
    omega0_axis: Literal["fixed", "uniform"] = "fixed"
    omega0_magnitude: tuple[float, float] | None = None
    omega0_magnitude_distribution: Literal["log-uniform", "uniform"] = "log-uniform"
    inertia: tuple[float, float, float] = ASTROBEE_INERTIA
    inertia_error: float = 0.0
    attitude0: tuple[float, float, float, float] | None = None
    position0: tuple[float, float, float] = (10.9, -6.7, 4.9)
    position0_std: float = 0.0
    velocity0: tuple[float, float, float] = (0.0, 0.0, 0.0)
    velocity0_std: float = 0.0
    dt: float = 0.1
    n_steps: int = 16000
    split: tuple[float, float, float] = (0.8, 0.1, 0.1)
    split_mode: Literal["time", "episodes"] = "time"
    sigma_position: float = 0.1
    sigma_attitude: float = 0.1
    noise_scale: float = 1.0
    measurement_every: int = 10
    dropout: float = 0.0
    burst_rate: float = 0.0
    burst_length: int = 0
    outlier_fraction: float = 0.0
    outlier_position_sigma: float = 1.0
    sign_flip_probability: float = 0.0
    noise_step_scale: float = 1.0
    measurement_covariance: bool = False
    kick_rate: float = 0.0
    kick_length: int = 0
    kick_sigma: float = 0.0
    kick_decay: float = 5.0
    free_substeps: int = 1
    dataset_seed: int = 0
    test_episodes: int = 20
    model_family: str = "ds1"
    tags: tuple[str, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        _check(isinstance(self.name, str) and self.name != "", "name", "a non-empty string", self.name)
        _check(self.dynamics in ("forced", "free"), "dynamics", "'forced' or 'free'", self.dynamics)
        for name in ("omega0", "position0", "velocity0"):
            set_(self, name, _vector(getattr(self, name), name, 3))
        inertia = _vector(self.inertia, "inertia", 3)
        _check(all(v > 0 for v in inertia), "inertia", "three positive moments (kg m^2)", self.inertia)
        a, b, c = sorted(inertia)
        _check(c <= a + b, "inertia", "physical: each moment <= sum of the other two", self.inertia)
        set_(self, "inertia", inertia)
        _check(self.omega0_frame in ("world", "body"), "omega0_frame", "'world' or 'body'", self.omega0_frame)
        _check(self.omega0_axis in ("fixed", "uniform"), "omega0_axis", "'fixed' or 'uniform'", self.omega0_axis)
        _check(self.omega0_magnitude_distribution in ("log-uniform", "uniform"), "omega0_magnitude_distribution",
               "'log-uniform' or 'uniform'", self.omega0_magnitude_distribution)
        if self.omega0_magnitude is not None:
            low, high = _vector(self.omega0_magnitude, "omega0_magnitude", 2)
            lowest = 0.0 if self.omega0_magnitude_distribution == "uniform" else 1e-9
            _check(lowest <= low <= high <= MAX_RATE, "omega0_magnitude",
                   f"a range (low, high) with {'0' if lowest == 0 else '0 <'} low <= high <= {MAX_RATE:g} rad/s"
                   + (" (log-uniform: low > 0)" if lowest else ""), self.omega0_magnitude)
            set_(self, "omega0_magnitude", (low, high))
        _check(self.omega0_axis == "uniform" or self.omega0_magnitude is None or any(self.omega0), "omega0",
               "non-zero when its magnitude is drawn about a fixed axis (omega0_axis = 'fixed')", self.omega0)
        _check(all(abs(v) <= MAX_RATE for v in self.omega0), "omega0", f"a rate of at most {MAX_RATE:g} rad/s per axis",
               self.omega0)
        e = self.inertia_error
        _check(_is_finite_number(e) and 0.0 <= e < 0.5 and (e == 0.0 or self.dynamics == "free"), "inertia_error",
               "a number in [0, 0.5), non-zero only with free dynamics", e)
        _check(c * (1 + e) <= (a + b) * (1 - e), "inertia_error",
               "small enough that every drawn inertia is physical", e)
        set_(self, "inertia_error", float(e))
        if self.attitude0 is not None:
            q = _vector(self.attitude0, "attitude0", 4)
            norm = math.sqrt(sum(v * v for v in q))
            _check(norm > 1e-9, "attitude0", "a non-zero quaternion (wxyz) or None", self.attitude0)
            set_(self, "attitude0", tuple(v / norm for v in q))
        for name in ("position0_std", "velocity0_std", "sigma_position", "sigma_attitude", "noise_scale",
                     "outlier_position_sigma", "noise_step_scale", "kick_sigma"):
            value = getattr(self, name)
            _check(_is_finite_number(value) and 0 <= value <= MAX_NOISE, name, f"a finite number in [0, {MAX_NOISE:g}]", value)
            set_(self, name, float(value))
        for name in ("sigma_position", "sigma_attitude"):  # what the measurements get: noise_scale x sigma
            _check(self.noise_scale * getattr(self, name) <= MAX_NOISE, "noise_scale",
                   f"small enough that noise_scale x {name} <= {MAX_NOISE:g}", self.noise_scale)
            _check(self.noise_step_scale * self.noise_scale * getattr(self, name) <= MAX_NOISE, "noise_step_scale",
                   f"small enough that noise_step_scale x noise_scale x {name} <= {MAX_NOISE:g}", self.noise_step_scale)
        _check(_is_finite_number(self.kick_decay) and self.kick_decay > 0, "kick_decay", "a finite number > 0 (s)",
               self.kick_decay)
        set_(self, "kick_decay", float(self.kick_decay))
        _check(_is_finite_number(self.dt) and self.dt > 0, "dt", "a finite number > 0 (s)", self.dt)
        set_(self, "dt", float(self.dt))
        for name, low in (("n_steps", 2), ("measurement_every", 1), ("burst_length", 0), ("test_episodes", 1),
                          ("free_substeps", 1), ("dataset_seed", 0), ("kick_length", 0)):
            value = getattr(self, name)
            _check(isinstance(value, int) and not isinstance(value, bool) and value >= low,
                   name, f"an integer >= {low}", value)
        for name in ("dropout", "burst_rate", "outlier_fraction", "sign_flip_probability", "kick_rate"):
            value = getattr(self, name)
            _check(_is_finite_number(value) and 0.0 <= value <= 1.0, name, "a number in [0, 1]", value)
            set_(self, name, float(value))
        _check(not self.has_kicks or self.dynamics == "forced", "dynamics",
               "'forced' when torque bursts are on (kick_rate, kick_length, kick_sigma)", self.dynamics)
        _check(not (self.dropout == 1.0), "dropout", "a number in [0, 1) (1 removes every measurement)",
               self.dropout)
        _check(self.split_mode in ("time", "episodes"), "split_mode", "'time' or 'episodes'", self.split_mode)
        split = _vector(self.split, "split", 3)
        _check(all(v > 0 for v in split) and abs(sum(split) - 1.0) < 1e-9, "split",
               "three positive fractions (train, val, test) summing to 1", self.split)
        set_(self, "split", split)
        bounds = self.split_bounds()
        _check(all(stop - start >= 2 for start, stop in bounds.values()), "split",
               "fractions giving every split at least 2 samples", self.split)
        _check(isinstance(self.measurement_covariance, bool), "measurement_covariance", "true or false",
               self.measurement_covariance)
        set_(self, "tags", tuple(str(t) for t in self.tags))

    # ------------------------------------------------------------------ derived values
    @property
    def sigma_position_effective(self) -> float:
        """Position noise standard deviation actually applied, m."""
        return self.noise_scale * self.sigma_position

    @property
    def sigma_attitude_effective(self) -> float:
        """Attitude noise standard deviation actually applied, rad per axis."""
        return self.noise_scale * self.sigma_attitude

    @property
    def has_kicks(self) -> bool:
        """True when unmodelled torque bursts perturb the rate (see the class docstring)."""
        return self.kick_rate > 0 and self.kick_length > 0 and self.kick_sigma > 0

    def noise_factor(self, steps: ArrayLike) -> Any:
        """The factor on the measurement noise standard deviations at global ``steps``:
        ``noise_step_scale`` in the middle third of each split (train, val, test), else 1."""
        import numpy as np

        steps = np.asarray(steps)
        factor = np.ones(steps.shape)
        if self.noise_step_scale == 1.0:
            return factor
        for name in SPLITS[:3]:
            start, stop = self.split_bounds()[name]
            length = stop - start
            inside = (steps >= start + length // 3) & (steps < start + 2 * length // 3)
            factor[inside] = self.noise_step_scale
        return factor

    def split_bounds(self) -> dict[str, tuple[int, int]]:
        """Half-open step ranges ``[start, stop)`` of the train, val, test and full splits (every
        one ``[0, n_steps)`` with ``split_mode = "episodes"``: a split is then a pool of whole
        episodes, :meth:`split_seeds`)."""
        n = self.n_steps
        if self.split_mode == "episodes":
            return {name: (0, n) for name in SPLITS}
        train_end = int(round(self.split[0] * n))
        val_end = int(round((self.split[0] + self.split[1]) * n))
        return {"train": (0, train_end), "val": (train_end, val_end), "test": (val_end, n), "full": (0, n)}

    def split_seeds(self, split: str, seeds: Iterable[int]) -> list[int]:
        """The episode seeds of episodes ``seeds`` of ``split``: the seeds themselves with
        ``split_mode = "time"`` (every split is a piece of the same episodes); with ``"episodes"``,
        ``SEED_POOLS[split] + i`` for episode ``i`` of the split's pool (:data:`SEED_POOLS`).
        Raises :class:`ConfigError` for an index outside the pool: a test seed of ``2**62`` or
        more would be a training or validation episode."""
        if split not in SPLITS:
            raise ConfigError(f"unknown split {split!r}; valid splits: {', '.join(SPLITS)}")
        seeds = [int(s) for s in seeds]
        if self.split_mode == "time":
            return seeds
        size = 2**62 if SEED_POOLS[split] == 0 else POOL_SIZE
        for seed in seeds:
            if not 0 <= seed < size:
                raise ConfigError(
                    f"episode {seed} is outside the {split} pool of episode-split scenario '{self.name}': its "
                    f"{split} episodes are 0 .. {size - 1} (larger seeds are other splits' episodes)")
        return [SEED_POOLS[split] + seed for seed in seeds]

    @property
    def has_rate_prior(self) -> bool:
        """True when each episode draws its initial rate (class docstring, "Prior")."""
        return self.omega0_axis == "uniform" or self.omega0_magnitude is not None

    def describe_prior(self) -> dict[str, str]:
        """The stated prior over each episode's truth, one line per quantity (SI units), as
        ``fkn-bench scenarios NAME`` prints it."""
        def vec(values: tuple[float, ...]) -> str:
            return "(" + ", ".join(f"{v:g}" for v in values) + ")"

        if self.has_rate_prior:
            magnitude = (f"|omega0| = {math.sqrt(sum(v * v for v in self.omega0)):g}" if self.omega0_magnitude is None
                         else f"{self.omega0_magnitude_distribution} in [{self.omega0_magnitude[0]:g}, "
                              f"{self.omega0_magnitude[1]:g}]")
            axis = "uniform on the sphere" if self.omega0_axis == "uniform" else f"fixed along {vec(self.omega0)}"
            rate = f"magnitude {magnitude} rad/s, axis {axis} ({self.omega0_frame} frame)"
        else:
            rate = f"fixed {vec(self.omega0)} rad/s ({self.omega0_frame} frame)"
        def spread(std: float) -> str:
            return f" + N(0, {std:g}^2) per axis" if std else " (fixed)"

        prior = {
            "rate": rate,
            "attitude": "uniform on SO(3)" if self.attitude0 is None else f"fixed {vec(self.attitude0)} (wxyz)",
            "position": f"{vec(self.position0)} m" + spread(self.position0_std),
            "velocity": f"{vec(self.velocity0)} m/s" + spread(self.velocity0_std),
        }
        if self.dynamics == "free":
            prior["inertia"] = (f"{vec(self.inertia)} kg m^2" + (f" x (1 + U(-{self.inertia_error:g}, "
                                f"{self.inertia_error:g})) per axis" if self.inertia_error else " (fixed)"))
        if self.split_mode == "episodes":
            prior["splits"] = ("whole episodes from disjoint seed pools: test (and reset(seed=s)) episode s is seed s, "
                               "train episode i seed 2**62 + i, val episode i seed 2**62 + 2**61 + i")
        else:
            train, val, test = (f"{100 * f:g}%" for f in self.split)
            prior["splits"] = f"pieces of each episode: train the first {train}, val the next {val}, test the last {test}"
        return prior

    # ------------------------------------------------------------------ conversions
    def replace(self, **changes: Any) -> Scenario:
        """A copy with ``changes`` applied (validated); unknown field names raise ConfigError."""
        _check_fields(changes)
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-compatible dict (tuples become lists)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(self).items()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Scenario:
        """Build from a dict such as :meth:`to_dict` output or a TOML table."""
        _check_fields(data)
        if "name" not in data:
            raise ConfigError("scenario field 'name' is required")
        return cls(**dict(data))

    def config_hash(self) -> str:
        """Short SHA-256 of the generating configuration (name, description, tags and test_episodes excluded;
        fields added since the first release are left out at their default value, so that the
        hashes of earlier configurations, which artefacts and stored results carry, still hold)."""
        payload = {
            k: v for k, v in self.to_dict().items()
            if k not in ("name", "description", "tags", "test_episodes") and _LATER_DEFAULTS.get(k, _NO_DEFAULT) != v
        }
        return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()[:16]


_NO_DEFAULT = object()
_LATER_DEFAULTS: dict[str, Any] = {
    "omega0_frame": "world", "inertia_error": 0.0, "noise_step_scale": 1.0, "kick_rate": 0.0, "kick_length": 0,
    "kick_sigma": 0.0, "kick_decay": 5.0, "omega0_axis": "fixed", "omega0_magnitude": None,
    "omega0_magnitude_distribution": "log-uniform", "velocity0_std": 0.0, "split_mode": "time",
    "measurement_covariance": False,
}
"""Fields added after the first release, with the defaults that leave them out of the hash."""


def _check_fields(names: Iterable[str]) -> None:
    """Raise :class:`ConfigError` naming the valid fields when ``names`` holds unknown ones."""
    known = {f.name for f in dataclasses.fields(Scenario)}
    unknown = sorted(set(names) - known)
    if unknown:
        raise ConfigError(f"unknown scenario field(s) {', '.join(unknown)}; valid fields: {', '.join(sorted(known))}")
