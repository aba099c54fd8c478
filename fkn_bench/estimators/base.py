"""The estimator API that every estimator of the project implements.

Two ways to use an estimator:

* batch: ``estimate(measurements, mask, dt) -> Estimates`` on whole sequences, batch first
  (``(B, T, 7)`` measurements, ``(B, T)`` validity);
* online: ``reset(dt=...)`` then ``step(observation) -> Estimate`` once per time step, e.g. in the
  Gymnasium loop (``env.step(estimate.mean)``).

Both give the same numbers for the same inputs (tested to 1e-12 for the built-in filters).
Conventions (see :mod:`fkn_bench.types`): states ``[q(wxyz), r, w(world), v]``, SI units;
covariances of the 13-dim state and of the 12-dim error ``[dtheta, dr, dw, dv]`` (world-frame
attitude error); innovations as 6-dim pose residuals ``[dtheta, dr]`` so that NIS compares across
filter variants. Each sequence initialises at its first usable measurement (attitude and position
from it, rates zero, the estimator's documented ``P0``); before it, the estimate is the prior
(identity attitude, zeros) with ``initialised = False``.

Divergence: no estimator emits a non-finite number. Where a filter's state stops being finite
(an overflow after gross outliers has moved it far from anything physical) the sequence restarts,
as a navigation filter is re-initialised when it diverges: from the step where it overflowed it
reports the prior (``initialised = False``) until its next usable measurement, where it
initialises as at the start (:func:`restart_diverged` in ``estimate``; the same rule in the online
``step``). ``Estimates.extras["restarted"]`` (``(B, T)`` bool, present only when a sequence
restarted) marks the steps where a restart happened, and
:attr:`RecursiveEstimator.restarts` counts the online ones.

Persistence: :meth:`Estimator.save` writes a JSON document (atomically) with ``format``,
``format_version``, the estimator ``name`` and its ``config``; :func:`load_estimator` reads it back
through the registry and refuses unknown formats or versions with a message that says so.
"""

from __future__ import annotations

import functools
import math
import numbers
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from fkn_bench.filters.base import FilterSteps, check_dt
from fkn_bench.filters.recursion import Carry, Steps, advance, start_carry
from fkn_bench.filters.pose import error_covariance_from_state, state_covariance_from_error
from fkn_bench.inputs import real_array, real_number
from fkn_bench.io import read_json, write_json_atomic
from fkn_bench.types import ArrayB, ArrayF, Bool, Float

__all__ = [
    "Estimate",
    "Estimates",
    "Estimator",
    "OnlineState",
    "RecursiveEstimator",
    "TIME_TOLERANCE",
    "check_dt",
    "ESTIMATOR_FORMAT",
    "ESTIMATOR_FORMAT_VERSION",
    "EstimatorFileError",
    "check_batch_inputs",
    "MAX_INTERVAL",
    "observation_time",
    "observation_valid",
    "parse_observation",
    "read_estimator_document",
    "restart_diverged",
]

ESTIMATOR_FORMAT = "fkn-bench-estimator"
ESTIMATOR_FORMAT_VERSION = 1


class EstimatorFileError(ValueError):
    """A saved estimator that cannot be read: missing, corrupt, or of an unknown format/version."""


@dataclass(frozen=True, eq=False, init=False)
class Estimate:
    """One online estimate (an immutable value; its arrays are read-only).

    Attributes:
        time: time of the estimate, s.
        mean: ``(13,)`` state estimate (unit quaternion).
        native_covariance: the covariance the filter carries: ``(13, 13)`` of the state for
            additive filters, ``(12, 12)`` of the error for the multiplicative EKF; None for an
            estimator that carries none (KalmanNet; ``covariance`` and ``error_covariance`` are
            then None too).
        initialised: False before the first usable measurement.
        updated: True when this step used a measurement.
    Properties ``covariance`` (13x13 state) and ``error_covariance`` (12x12 error
    ``[dtheta, dr, dw, dv]``) convert on first access.
    """

    time: float
    mean: ArrayF
    native_covariance: ArrayF | None
    initialised: bool
    updated: bool

    def __init__(self, time: float, mean: ArrayF, native_covariance: ArrayF | None, initialised: bool, updated: bool) -> None:
        mean.flags.writeable = False  # one dict update: per step
        if native_covariance is not None:
            native_covariance.flags.writeable = False
        self.__dict__.update(time=time, mean=mean, native_covariance=native_covariance, initialised=initialised, updated=updated)

    @functools.cached_property
    def covariance(self) -> ArrayF | None:
        if self.native_covariance is None or self.native_covariance.shape == (13, 13):
            return self.native_covariance
        return state_covariance_from_error(self.mean[:4], self.native_covariance)

    @functools.cached_property
    def error_covariance(self) -> ArrayF | None:
        if self.native_covariance is None or self.native_covariance.shape == (12, 12):
            return self.native_covariance
        return error_covariance_from_state(self.mean[:4], self.native_covariance)


@dataclass(frozen=True, eq=False)
class Estimates:
    """Batch estimates, batch first (numpy, float64).

    Attributes:
        means: ``(B, T, 13)``.
        covariances: ``(B, T, 13, 13)`` or None.
        error_covariances: ``(B, T, 12, 12)`` or None.
        innovations: ``(B, T, 6)`` pose innovations ``[dtheta, dr]`` (rad, m) where
            ``innovation_mask`` is True, or None.
        innovation_covariances: ``(B, T, 6, 6)`` or None.
        innovation_mask: ``(B, T)`` True where a measurement update happened.
        initialised: ``(B, T)`` True from each sequence's initialisation on.
        extras: estimator-specific arrays (e.g. adapted noise), keyed by name.
    """

    means: Float[ArrayF, "B T 13"]
    covariances: Float[ArrayF, "B T 13 13"] | None = None
    error_covariances: Float[ArrayF, "B T 12 12"] | None = None
    innovations: Float[ArrayF, "B T m"] | None = None
    innovation_covariances: Float[ArrayF, "B T m m"] | None = None
    innovation_mask: Bool[ArrayB, "B T"] | None = None
    initialised: Bool[ArrayB, "B T"] | None = None
    extras: Mapping[str, ArrayF] = field(default_factory=dict)

    @property
    def batch_size(self) -> int:
        return self.means.shape[0]

    @property
    def n_steps(self) -> int:
        return self.means.shape[1]


def _finite_rows(estimates: Estimates) -> ArrayB:
    """``(B, T)`` True where the mean, the covariances and the innovations an estimate carries
    are all finite."""
    ok = np.isfinite(estimates.means).all(-1)
    for array in (estimates.covariances, estimates.error_covariances, estimates.innovations, estimates.innovation_covariances):
        if array is not None:
            ok &= np.isfinite(array).reshape(ok.shape + (-1,)).all(-1)
    return ok


def restart_diverged(
    estimates: Estimates, rerun: Callable[..., Estimates], measurements: ArrayF, mask: ArrayB, *,
    per_step_inputs: tuple[ArrayF, ...] = (),
) -> Estimates:
    """``estimates`` with every sequence that stopped being finite restarted (module docstring).

    ``rerun(measurements, mask, *inputs)`` filters a sub-batch from scratch (the estimator's own
    ``estimate`` with the same ``dt``, which applies this rule itself); ``inputs`` are
    ``per_step_inputs`` (other ``(B, T, ...)`` arrays, e.g. measurement covariances) sliced like
    the measurements. A sequence whose outputs
    are first non-finite at step ``t0`` is filtered again from ``t0`` on, as a new sequence that
    initialises at its first usable measurement from ``t0``; its outputs replace those from ``t0``
    on. Each restart starts later than the previous one (a fresh sequence is finite at its first
    step: the prior or a measurement), so this ends. Costs one finiteness check when nothing
    diverged.
    """
    ok = _finite_rows(estimates)
    if ok.all():
        return estimates
    per_step = {
        name: getattr(estimates, name)
        for name in ("means", "covariances", "error_covariances", "innovations", "innovation_covariances",
                     "innovation_mask", "initialised")
    }
    per_step = {name: array.copy() for name, array in per_step.items() if array is not None}
    batch, steps = ok.shape
    extras = {
        name: np.array(value, copy=True) for name, value in estimates.extras.items()
    }
    restarted = extras.get("restarted")
    restarted = np.zeros((batch, steps), dtype=bool) if restarted is None else restarted.astype(bool)
    for row in np.flatnonzero(~ok.all(1)):
        t0 = int(np.argmin(ok[row]))
        fresh = rerun(measurements[row : row + 1, t0:], mask[row : row + 1, t0:],
                      *(array[row : row + 1, t0:] for array in per_step_inputs))
        for name, array in per_step.items():
            array[row, t0:] = getattr(fresh, name)[0]
        for name, array in extras.items():
            if name != "restarted" and array.shape[:2] == (batch, steps) and name in fresh.extras:
                array[row, t0:] = fresh.extras[name][0]
        restarted[row, t0] = True
        if "restarted" in fresh.extras:
            restarted[row, t0:] |= fresh.extras["restarted"][0]
    extras["restarted"] = restarted
    return Estimates(**per_step, extras=extras)


def check_batch_inputs(measurements: Any, mask: Any, dt: Any) -> tuple[ArrayF, ArrayB, float]:
    """Validate ``estimate()`` inputs: ``(B, T, 7)`` float measurements, ``(B, T)`` mask, ``dt > 0``.

    Returns float64 measurements, a bool mask and ``dt`` as float; raises ``ValueError`` naming
    the problem (measurements of another dtype than a real integer or floating one, as
    :func:`parse_observation`'s pose; a ``dt`` that is not a real number,
    :func:`fkn_bench.inputs.real_number`; wrong shapes, empty sequences, a non-finite or non-positive ``dt``). Entries
    outside the mask may hold anything (NaN included); non-finite entries inside it are handled
    by the documented rule of the filters (the update is skipped).
    """
    z = real_array(measurements, "measurements", shape_text="(B, T, 7)")
    if z.ndim != 3 or z.shape[-1] != 7:
        hint = " (use measurements[None] for a single sequence)" if z.ndim == 2 else ""
        raise ValueError(f"measurements must have shape (B, T, 7) (got {z.shape}){hint}")
    if z.shape[0] == 0 or z.shape[1] == 0:
        raise ValueError(f"measurements hold no sequences or no time steps (shape {z.shape})")
    m = np.asarray(mask)
    if m.shape != z.shape[:2]:
        raise ValueError(f"mask must have shape {z.shape[:2]} to match the measurements (got {m.shape})")
    if m.dtype != np.bool_:
        if not np.isin(m, (0, 1)).all():
            raise ValueError("mask must be boolean (or 0/1)")
        m = m.astype(bool)
    return z, m, check_dt(real_number(dt, "dt", "a number"))


def parse_observation(observation: Any) -> tuple[ArrayF | None, float | None]:
    """Measurement ``(7,)`` (None when missing) and time (None when absent) of an observation.

    Accepts a Gymnasium observation dict (``pose``, ``valid``, ``time``) or a ``(7,)`` array
    (all NaN when missing). The dict's fields are checked where they enter (``ValueError`` naming
    the field): the pose must be 7 numbers of a real integer or floating dtype, of shape exactly
    ``(7,)`` (the environments' action rules, :func:`fkn_bench.inputs.real_array`: strings,
    bools, complex numbers, objects, values float64 cannot hold such as ``10**400``, 0-d arrays
    and nested lists are refused; NaN and inf pass, and the filters skip such a measurement by
    their documented rule), ``time``, when present, must be a finite real number of seconds (a number, not a
    string; see :func:`observation_time`) and ``valid``, when present, a bool or 0/1 (see
    :func:`observation_valid`; ``"False"`` or NaN are refused, not counted valid). Anything else
    is refused with a ``ValueError`` too.
    """
    if type(observation) is np.ndarray:  # the common online case first: a (7,) array
        pose, valid, time = observation, True, None
    elif isinstance(observation, dict):
        try:
            pose = observation["pose"]
        except KeyError:
            raise ValueError(f"observation dict needs a 'pose' entry (has {sorted(observation, key=str)})") from None
        valid = observation_valid(observation["valid"]) if "valid" in observation else True
        time = observation.get("time")
        time = None if time is None else observation_time(time)
    elif isinstance(observation, Mapping):
        return parse_observation(dict(observation))
    else:
        pose, valid, time = observation, True, None
    if type(pose) is not np.ndarray or pose.dtype != np.float64 or pose.shape != (7,):
        pose = real_array(pose, "observation 'pose'", (7,), entry="pose")
    if not valid or (math.isnan(pose[0]) and np.isnan(pose).all()):
        return None, time
    return pose, time


def observation_time(value: Any) -> float:
    """An observation's ``time`` as a float: a finite real number of seconds (``int``, ``float``,
    a numpy integer or float, or a 0-d array of one: :func:`fkn_bench.inputs.real_number`). A
    string (``"nan"``, ``"0.5"``), a bool, an array of another shape, a value float64 cannot hold
    (``10**400``), NaN and +-inf are refused with a ``ValueError`` naming the field."""
    if type(value) is not float:
        value = real_number(value, "observation 'time'", "a real number of seconds")
    if not math.isfinite(value):
        raise ValueError(f"observation 'time' must be a finite number of seconds (got {value})")
    return value


def observation_valid(value: Any) -> bool:
    """An observation's ``valid`` flag as a bool: ``True``/``False``, a numpy bool, or a number
    equal to 0 or 1 (``np.int64(1)`` from the Gymnasium environments; also in a 0-d array).
    Anything else (``"False"``, ``None``, NaN, 2, a list) is refused with a ``ValueError``
    naming the field rather than counted valid."""
    if type(value) is bool:
        return value
    if isinstance(value, np.ndarray) and value.shape == ():
        value = value[()]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, numbers.Real) and (value == 0 or value == 1):
        return bool(value == 1)
    raise ValueError(f"observation 'valid' must be True/False or 0/1 (got {value!r})")


class Estimator(ABC):
    """Base class of estimators (see module docstring).

    Subclasses set ``name`` and ``description`` and implement :meth:`estimate`, :meth:`reset`,
    :meth:`step` and :meth:`to_config`; estimators with learned or tuned values override
    :meth:`save` and :meth:`load` when a JSON config cannot hold them.
    """

    name: str = "estimator"
    description: str = ""
    causal: bool = True
    """False for an estimator whose estimate at a step uses later measurements (a smoother): an
    offline reference, not a filter; it has no online ``step`` and reports label it."""
    recorded: bool = False
    """True for another program's recorded output (:class:`fkn_bench.estimators.external.ExternalEstimates`):
    scored, not timed; the harness leaves its costs empty."""
    uses_measurement_covariances: bool = False
    """True for an estimator whose ``estimate`` takes ``measurement_covariances`` (``(B, T, 6, 6)``,
    :attr:`fkn_bench.envs.Episodes.measurement_covariances`; a Kalman estimator with
    ``measurement_noise="message"``): the harness passes the episodes' stated covariances."""

    @abstractmethod
    def estimate(self, measurements: Float[ArrayF, "B T 7"], mask: Bool[ArrayB, "B T"], dt: float) -> Estimates:
        """Filter whole sequences: ``measurements (B, T, 7)``, ``mask (B, T)`` -> :class:`Estimates`."""

    @abstractmethod
    def reset(self, *, dt: float) -> None:
        """Start a new online sequence with time step ``dt`` (s)."""

    @abstractmethod
    def step(self, observation: Any) -> Estimate:
        """Consume one observation (see :func:`parse_observation`) and return the estimate."""

    @abstractmethod
    def to_config(self) -> dict[str, Any]:
        """JSON-compatible configuration from which :meth:`from_config` rebuilds the estimator."""

    @classmethod
    def from_config(cls, config: Mapping[str, Any]) -> Estimator:
        """Rebuild from :meth:`to_config` output."""
        return cls(**dict(config))

    def save(self, path: str | Path) -> Path:
        """Write the estimator as JSON (atomically) and return the path."""
        cls = type(self)
        document = {
            "format": ESTIMATOR_FORMAT,
            "format_version": ESTIMATOR_FORMAT_VERSION,
            "name": self.name,
            "class": f"{cls.__module__}:{cls.__qualname__}",
            "config": self.to_config(),
        }
        return write_json_atomic(path, document)

    @classmethod
    def load(cls, path: str | Path) -> Estimator:
        """Read an estimator written by :meth:`save` (see :func:`read_estimator_document`).

        Raises :class:`EstimatorFileError` when the file was saved by another class (use
        :func:`~fkn_bench.estimators.load_estimator`, which picks the class from the file) or when
        its config does not rebuild the estimator.
        """
        document = read_estimator_document(path)
        target = f"{cls.__module__}:{cls.__qualname__}"
        saved = document.get("class", target)
        if saved != target:
            raise EstimatorFileError(f"{path} holds a {saved} estimator, not a {target}; load it with load_estimator()")
        from fkn_bench.config_values import check_arguments, init_annotations

        try:  # the values must be of the kinds the constructor takes: a std is a number, not true or "0.1"
            check_arguments(init_annotations(cls), document["config"], "")
            return cls.from_config(document["config"])
        except (TypeError, ValueError) as exc:
            raise EstimatorFileError(f"{path}: invalid {cls.__name__} config: {exc}") from None

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r})"


TIME_TOLERANCE = 1e-6
"""Online observation intervals within this many seconds of ``dt`` are taken as ``dt``."""

MAX_INTERVAL = 1e6
"""The longest online observation interval, s (11.6 days): a longer one is refused as a unit or
clock mistake (e.g. a Unix timestamp after times counted from 0); no filter's prediction over it
means anything, and one over ~1e308 s overflows."""


class OnlineState(NamedTuple):
    """An online estimator's state after a step (an immutable value): the time (s) and the
    recursion's carry (:class:`~fkn_bench.filters.recursion.Carry`: the filter's own batch-1
    state, whether the sequence has initialised, its gate rejections)."""

    time: float
    carry: Carry


class _FilterSteps(FilterSteps):
    """The default online step functions: ``estimator.filter``'s (a
    :class:`~fkn_bench.filters.KalmanFilter`) on numpy batch-1 arrays, with the step's noise
    ``estimator._online_noise = (Q, R, P0)`` read at every call (it may change per step)."""

    def __init__(self, estimator: Any) -> None:
        super().__init__(estimator.filter)
        self.estimator = estimator

    def noise(self, t: int) -> tuple[ArrayF, ArrayF, ArrayF]:
        return self.estimator._online_noise


class RecursiveEstimator(Estimator):
    """An estimator whose online ``reset``/``step`` is a filter's one-step function: the one
    online recursion of the project (every built-in estimator uses it).

    Rules of :meth:`step`: steps are taken ``dt`` apart; when an observation carries a ``time``,
    it must be a finite number (:func:`parse_observation`) that increases by at most
    :data:`MAX_INTERVAL` (``ValueError`` naming the time otherwise), and an interval that differs
    from ``dt`` by more than :data:`TIME_TOLERANCE` is predicted over its actual length. A refused
    step (a bad ``time``, ``valid`` or ``pose``) leaves the estimator as it was, so the next
    valid step continues the sequence. The measurement is cleaned by :meth:`_online_sanitize`
    (the model's rule; unusable measurements skip the update). Each step is one iteration, at
    batch 1, of the project's one recursion (:func:`fkn_bench.filters.recursion.advance`: the
    first step starts from :meth:`_online_prior` without a prediction, later steps predict first;
    the sequence initialises at its first usable measurement, later ones update, a chi-square gate
    and the lost-track restart as in the batch run) on the step functions of
    :meth:`_online_steps`: by default the filter variant's on numpy arrays; an estimator with
    another state returns its own. Measurements reach them sanitised, as ``(1, 7)`` arrays.
    """

    _dt: float | None = None
    _online: OnlineState | None = None
    _steps: Steps | None = None
    restarts: int = 0
    """Online restarts since :meth:`reset` (module docstring: a state that stopped being finite)."""

    def reset(self, *, dt: float) -> None:
        """Start a new online sequence with time step ``dt`` (s): a finite real number in
        ``(0, MAX_INTERVAL]`` (:func:`fkn_bench.inputs.real_number`: not a bool or a string;
        ``ValueError`` naming ``dt`` otherwise)."""
        step = check_dt(real_number(dt, "dt", "a number"))  # (a bool, a string or 10**400: named)
        if step > MAX_INTERVAL:
            raise ValueError(f"dt must be at most MAX_INTERVAL = {MAX_INTERVAL:g} s (got {dt!r})")
        self._dt = step
        self._online = None
        self.restarts = 0

    def step(self, observation: Any) -> Estimate:
        if self._dt is None:
            raise RuntimeError("call reset(dt=...) before step()")
        pose, time = parse_observation(observation)
        z = None if pose is None else self._online_sanitize(pose[None])
        previous = self._online
        interval = self._dt
        if previous is None:
            now = 0.0 if time is None else time
        else:
            now = previous.time + self._dt if time is None else time
            interval = now - previous.time
            if not interval > 0:
                raise ValueError(f"observation time {now} does not increase (previous {previous.time})")
            if interval > MAX_INTERVAL:
                raise ValueError(
                    f"observation time {now} is {interval:.6g} s after the previous one ({previous.time}); "
                    f"intervals over MAX_INTERVAL = {MAX_INTERVAL:g} s are refused (reset() starts a new sequence)"
                )
            if abs(interval - self._dt) <= TIME_TOLERANCE:
                interval = self._dt
        self._online_observe(z)  # after the checks: a refused step leaves the estimator as it was
        if previous is None or self._steps is None:
            self._steps = self._online_steps()  # (once per sequence: the online step is a hot path)
        steps = self._steps
        carry = self._online_start(steps) if previous is None else previous.carry
        started = bool(carry.initialised[0])
        usable = _NONE if z is None else _ONE
        starts = usable if z is not None and not started else _NONE
        carry, used = advance(steps, carry, _NO_POSE if z is None else z, usable, starts, 0, interval,
                              predict=previous is not None, any_start=starts is _ONE,
                              any_update=z is not None and started, all_update=z is not None and started)
        updated = used is not None and bool(used[0])
        mean, covariance = self._online_report(carry.state)
        if not _reportable(mean, covariance):
            # diverged (module docstring): restart from the prior, initialising from this
            # step's measurement when it is usable
            carry, updated = self._online_start(steps), False
            if z is not None:
                carry = carry._replace(state=steps.initial(carry.state, z, 0), initialised=_ONE)
            self.restarts += 1
            mean, covariance = self._online_report(carry.state)
        self._online = OnlineState(now, carry)
        mean = mean.copy()
        w, x, y, z = mean[0:4].tolist()
        mean[0:4] /= math.sqrt(w * w + x * x + y * y + z * z)
        return Estimate(time=now, mean=mean, native_covariance=covariance, initialised=bool(carry.initialised[0]),
                        updated=updated)

    def _online_start(self, steps: Steps) -> Carry:
        """The carry of a new sequence: the prior, not initialised, no gate rejections."""
        return start_carry(steps, self._online_prior(), _NONE)

    def _online_steps(self) -> Steps:
        """The step functions of the online recursion (batch 1); by default the filter's
        (:class:`_FilterSteps`); estimators with another state return their own."""
        return _FilterSteps(self)

    def _online_sanitize(self, z: ArrayF) -> ArrayF | None:
        """The measurement ``(1, 7)`` cleaned by the model's rule, or None when unusable."""
        out, usable = self.filter.model.sanitize(z, _ONE)  # type: ignore[attr-defined]
        return out if usable[0] else None

    def _online_observe(self, z: ArrayF | None) -> None:
        """Called first in every step with the sanitised measurement (None when unusable)."""

    # the default step functions: a filter variant (``self.filter``, a
    # :class:`~fkn_bench.filters.KalmanFilter`) stepped on numpy arrays with the step's noise
    # ``self._online_noise = (Q, R, P0)``
    _online_noise: tuple[ArrayF, ArrayF, ArrayF]

    def _online_prior(self) -> Any:
        """The filter state before the first step's measurement."""
        return self.filter.prior(1, self._online_noise[2], np.float64)  # type: ignore[attr-defined]

    def _online_report(self, state: Any) -> tuple[ArrayF, ArrayF]:
        """The mean ``(13,)`` and the native covariance (read-only: the steps are pure)."""
        return state.mean[0], state.covariance[0]


_ONE = np.ones(1, dtype=bool)
_NONE = np.zeros(1, dtype=bool)
_NO_POSE = np.zeros((1, 7))
for _constant in (_ONE, _NONE, _NO_POSE):
    _constant.flags.writeable = False


def _reportable(mean: ArrayF, covariance: ArrayF | None) -> bool:
    """True when an online state is finite and its quaternion's norm neither zero nor overflowing."""
    if not (np.isfinite(mean).all() and (covariance is None or np.isfinite(covariance).all())):
        return False
    w, x, y, z = mean[0:4].tolist()
    return 0.0 < w * w + x * x + y * y + z * z < math.inf


def read_estimator_document(path: str | Path) -> dict[str, Any]:
    """Read and check a saved estimator document; raises :class:`EstimatorFileError`."""
    path = Path(path)
    try:
        document = read_json(path)
    except (OSError, ValueError) as exc:
        raise EstimatorFileError(f"cannot read estimator file {path}: {exc}") from None
    if not isinstance(document, dict) or document.get("format") != ESTIMATOR_FORMAT:
        raise EstimatorFileError(f"{path} is not an fkn-bench estimator file (no format '{ESTIMATOR_FORMAT}')")
    version = document.get("format_version")
    if version != ESTIMATOR_FORMAT_VERSION:
        raise EstimatorFileError(
            f"{path} has estimator format version {version!r}; this fkn-bench reads version "
            f"{ESTIMATOR_FORMAT_VERSION} (re-save it with a matching fkn-bench)"
        )
    if not isinstance(document.get("config"), dict) or not isinstance(document.get("name"), str):
        raise EstimatorFileError(f"{path} lacks the estimator 'name' or 'config'")
    return document

