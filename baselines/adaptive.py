"""The adaptive EKF recursion shared by the online adaptive baselines, and its estimator.

An adaptive filter is the paper's additive EKF (FlexKalmanNet eqs. 1-5) whose noise covariances
are re-estimated while it filters. The recursion is common; what differs between methods is a
small strategy object, a :class:`NoiseRule`, that decides which ``R`` (and ``P-``) the update
uses and how the noise estimates change after it:

* :class:`~fkn_bench.baselines.sage_husa.SageHusaRule` (Sage & Husa 1969, with a forgetting
  factor);
* :class:`~fkn_bench.baselines.akhlaghi.AkhlaghiRule` (Akhlaghi, Zhou & Huang 2017);
* :class:`~fkn_bench.baselines.vbakf.VBAKFRule` (Huang, Zhang, Wu & Chambers 2018, IEEE TAC
  63(2)).

Conventions: those of :meth:`fkn_bench.filters.KalmanFilter.run` (predict-only steps without a
usable measurement, initialisation at the first usable one with ``P0``, measurements cleaned once
by the model's ``sanitize``), with the update of :func:`kalman_update`. Before every innovation
the measurement is aligned with the prediction (the pose model flips the measured quaternion when
``z_q . q- < 0``).

The noise starts from the filter's configured standard deviations (by default the model's
layout: for the pose model the paper's manual tuning, ``sigma_R = 0.1``, ``sigma_Q = 0.005``
for ``q`` and ``w`` and ``1e-4`` for ``r`` and ``v``, FlexKalmanNet section 4.3).

Multi-rate measurements. The papers update their noise estimates at every step; the benchmark
measures every ``M`` steps (10 on ds1). Process-noise rules that compare an update's correction
with one step's ``Q`` divide it by the number ``M`` of predictions since the previous update
(for ``F`` near the identity the prediction adds about ``M Q``); with a measurement at every
step (``M = 1``) they are the published rules exactly.

Everything runs in numpy on a leading batch axis: :meth:`AdaptiveKalmanFilter.run` filters all
sequences of a batch at once, and :meth:`AdaptiveKalmanFilter.step` is the same code that the
online ``step()`` of :class:`AdaptiveEKFEstimator` runs with a batch of one (the tests hold the
two to 1e-12).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import numpy as np

from fkn_bench.estimators.base import Estimates, RecursiveEstimator, check_batch_inputs, restart_diverged
from fkn_bench.estimators.kalman import KalmanEstimator, filter_result_to_estimates
from fkn_bench.filters.base import FilterState, KalmanFilter, gate_threshold
from fkn_bench.filters.recursion import Proposal, scan, start_carry
from fkn_bench.filters.ekf import ekf_predict, joseph_update
from fkn_bench.models.base import StateSpaceModel
from fkn_bench.models.pose_twist import PoseTwistModel
from fkn_bench.linalg import symmetrize
from fkn_bench.types import ArrayB, ArrayF

__all__ = [
    "AdaptiveEKFEstimator",
    "AdaptiveKalmanFilter",
    "AdaptiveResult",
    "AdaptiveState",
    "KalmanUpdate",
    "NoiseRule",
    "UpdateContext",
    "batched",
    "clamp_eigenvalues",
    "kalman_update",
    "outer",
]

Noise = dict[str, ArrayF]
"""A rule's adapted quantities, each an array with the batch axis first."""


# ---------------------------------------------------------------------------------------------
# small batched helpers
def outer(a: ArrayF) -> ArrayF:
    """``a a^T`` for vectors ``(B, k)`` -> ``(B, k, k)``."""
    return a[:, :, None] * a[:, None, :]


def batched(M: ArrayF, batch: int) -> ArrayF:
    """``batch`` writable copies of ``M`` along a new leading axis."""
    return np.broadcast_to(M, (batch,) + M.shape).copy()


def clamp_eigenvalues(M: ArrayF, floor: ArrayF) -> ArrayF:
    """Symmetric ``M (B, k, k)`` with its eigenvalues raised to at least ``floor (B,)``: the
    nearest matrix (in the Frobenius norm) whose eigenvalues are all ``>= floor``. Rows whose
    eigenvalues are all above the floor come back unchanged."""
    w, V = np.linalg.eigh(M)
    low = w < floor[:, None]
    if not low.any():
        return M
    clamped = (V * np.maximum(w, floor[:, None])[:, None, :]) @ V.swapaxes(1, 2)
    return np.where(low.any(1)[:, None, None], symmetrize(clamped), M)


class KalmanUpdate(NamedTuple):
    """Result of one measurement update of a batch of ``b`` rows.

    Attributes:
        x: ``(b, n)`` posterior means (normalised by the model).
        P: ``(b, n, n)`` posterior covariances (Joseph form, projected, symmetrised).
        S: ``(b, m, m)`` innovation covariances ``H P- H^T + R`` of the gain.
        K: ``(b, n, m)`` gains.
    """

    x: ArrayF
    P: ArrayF
    S: ArrayF
    K: ArrayF


def kalman_update(model: StateSpaceModel, x: ArrayF, P: ArrayF, nu: ArrayF, R: ArrayF) -> KalmanUpdate:
    """Kalman update of ``x (b, n)``, ``P (b, n, n)`` with innovation ``nu (b, m)`` and
    measurement noise ``R (b, m, m)``: the filters' update step
    (:func:`fkn_bench.filters.ekf.joseph_update`: gain ``K = P H^T S^-1``, Joseph form and the
    model's normalisation in one product; Bucy & Joseph 1968; Simon, Optimal State Estimation,
    2006, eq. 5.19)."""
    H = None if model.observed is not None else model.H
    return KalmanUpdate(*joseph_update(x, P, nu, R, H=H, observed=model.observed, normalize=model.normalize))


def projected_covariance(model: StateSpaceModel, P: ArrayF) -> ArrayF:
    """``H P H^T`` for ``P (b, n, n)`` (exactly symmetric when ``P`` is)."""
    if model.observed is not None:
        return P[:, model.observed, model.observed]
    return symmetrize(model.H @ P @ model.H.T)


# ---------------------------------------------------------------------------------------------
# noise rules
@dataclass(frozen=True, eq=False)
class UpdateContext:
    """What a :class:`NoiseRule` sees at a measurement update of ``b`` rows.

    Attributes:
        model: the state-space model (its functions run on these numpy arrays).
        x_pred: ``(b, n)`` predicted means.
        P_pred: ``(b, n, n)`` predicted covariances (with the rule's current ``Q``).
        z: ``(b, m)`` measurements, sanitised and aligned with the prediction.
        nu: ``(b, m)`` innovations ``z - H x-``.
        steps: ``(b,)`` predictions since the previous update (or the initialisation), >= 1.
    """

    model: StateSpaceModel
    x_pred: ArrayF
    P_pred: ArrayF
    z: ArrayF
    nu: ArrayF
    steps: ArrayF


class NoiseRule(ABC):
    """How a method adapts the noise (see module docstring). Subclasses set ``knobs``, the names
    of their keyword arguments, each stored as the attribute of that name."""

    name: ClassVar[str] = "rule"
    knobs: ClassVar[tuple[str, ...]] = ()
    adapts_q: bool = False

    def initial(self, batch: int, Q0: ArrayF, R0: ArrayF) -> Noise:
        """The rule's quantities for ``batch`` fresh sequences from the starting ``Q0 (n, n)``,
        ``R0 (m, m)`` (by default ``Q`` and ``R``, adapted in place of the starting values)."""
        return {"R": batched(R0, batch), "Q": batched(Q0, batch)}

    def process_noise(self, noise: Noise) -> ArrayF:
        """``Q (B, n, n)`` the prediction uses."""
        return noise["Q"]

    def measurement_noise(self, noise: Noise) -> ArrayF:
        """The current estimate of ``R (B, m, m)`` (reported in the estimates' extras)."""
        return noise["R"]

    @abstractmethod
    def update(self, ctx: UpdateContext, noise: Noise) -> tuple[KalmanUpdate, Noise]:
        """The measurement update of ``ctx``'s rows and their new noise quantities."""

    def config(self) -> dict[str, Any]:
        """The rule's knobs (JSON-compatible)."""
        return {key: getattr(self, key) for key in self.knobs}


def floor_from(matrix: ArrayF, fraction: float) -> float:
    """Eigenvalue floor: ``fraction`` times the smallest diagonal entry of ``matrix``."""
    return float(fraction) * float(np.min(np.diag(matrix)))


def check_range(name: str, value: float, *, low: float = 0.0, high: float = 1.0, closed_low: bool = False, closed_high: bool = True) -> float:
    """``value`` as a finite float in the interval (``(low, high]`` by default), else ValueError.
    A number is an ``int`` or a ``float`` (numpy's too), never a bool or a numeric string: a
    parameter file's ``true`` or ``"0.99"`` is refused, not read as 1 or 0.99."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name} must be a number (got {value!r})")
    try:
        number = float(value)
    except OverflowError:  # an integer beyond float range
        raise ValueError(f"{name} must be in the range of a float (got an integer of {len(str(value))} digits)") from None
    ok_low = number >= low if closed_low else number > low
    ok_high = number <= high if closed_high else number < high
    if not (math.isfinite(number) and ok_low and ok_high):
        lo, hi = ("[" if closed_low else "("), ("]" if closed_high else ")")
        raise ValueError(f"{name} must be in {lo}{low}, {high}{hi} (got {value!r})")
    return number


def check_int(name: str, value: int, minimum: int) -> int:
    """``value`` as an integer ``>= minimum`` (bools, strings and fractional numbers refused), else
    ValueError."""
    integral = isinstance(value, (int, np.integer)) or (isinstance(value, (float, np.floating)) and float(value).is_integer())
    if isinstance(value, (bool, np.bool_)) or not integral or int(value) < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum} (got {value!r})")
    return int(value)


def check_flag(name: str, value: bool) -> bool:
    """``value`` as a bool: ``True`` or ``False`` only (a parameter file's ``"false"`` or ``0``
    would otherwise switch a rule on or off by accident), else ValueError."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be true or false (got {value!r})")
    return bool(value)


# ---------------------------------------------------------------------------------------------
# the recursion
class AdaptiveState(NamedTuple):
    """A batch of adaptive-filter states at one time (an immutable value; whether each row has
    initialised and its gate rejections are the recursion's :class:`~fkn_bench.filters.recursion.Carry`).

    Attributes:
        x: ``(B, n)`` means.
        P: ``(B, n, n)`` covariances.
        since: ``(B,)`` predictions since the last update or initialisation.
        noise: the rule's adapted quantities (:data:`Noise`).
    """

    x: ArrayF
    P: ArrayF
    since: ArrayF
    noise: Mapping[str, ArrayF]


@dataclass(frozen=True, eq=False)
class AdaptiveResult:
    """Output of :meth:`AdaptiveKalmanFilter.run` (batch first, numpy).

    Attributes:
        means: ``(B, T, n)`` posterior means.
        covariances: ``(B, T, n, n)``.
        innovations: ``(B, T, m)`` (zero where no update).
        innovation_covariances: ``(B, T, m, m)`` (identity where no update).
        prior_means: ``(B, T, n)``.
        updated, initialised: ``(B, T)``.
        r_diag: ``(B, T, m)`` diagonal of the current ``R`` estimate after each step.
        q_diag: ``(B, T, n)`` diagonal of the current ``Q`` after each step (None when the rule
            keeps ``Q`` fixed).
        final: the state after the last step.
    """

    means: ArrayF
    covariances: ArrayF
    innovations: ArrayF
    innovation_covariances: ArrayF
    prior_means: ArrayF
    updated: ArrayB
    initialised: ArrayB
    r_diag: ArrayF
    q_diag: ArrayF | None
    final: AdaptiveState


def _put(noise: Mapping[str, ArrayF], rows: ArrayF, values: Mapping[str, ArrayF]) -> Noise:
    out = {key: value.copy() for key, value in noise.items()}
    for key, value in out.items():
        value[rows] = values[key]
    return out


def _std_matrix(name: str, values: Sequence[float] | None, default: Sequence[float]) -> ArrayF:
    return np.diag(np.square(KalmanEstimator._check_std(name, values, default)))


class AdaptiveKalmanFilter:
    """The adaptive EKF recursion over a model (see module docstring).

    Args:
        rule: the method's :class:`NoiseRule`.
        model: a :class:`~fkn_bench.models.base.StateSpaceModel` (run on numpy arrays; default
            the paper's pose-and-twist model).
        q_std, r_std, p0_std: starting standard deviations of ``Q``, ``R`` and ``P0`` (default:
            the model layout's, for the pose model the paper's manual tuning).
    """

    def __init__(
        self,
        rule: NoiseRule,
        *,
        model: StateSpaceModel | None = None,
        q_std: Sequence[float] | None = None,
        r_std: Sequence[float] | None = None,
        p0_std: Sequence[float] | None = None,
    ) -> None:
        self.rule = rule
        self.model = model if model is not None else PoseTwistModel()
        layout = self.model.layout
        self.Q0 = _std_matrix("q_std", q_std, layout.q_default)
        self.R0 = _std_matrix("r_std", r_std, layout.r_default)
        self.P0 = _std_matrix("p0_std", p0_std, layout.p0_default)

    covariance_dim = KalmanFilter.covariance_dim
    innovation_dim = KalmanFilter.innovation_dim

    def prior(self, batch: int) -> AdaptiveState:
        """``batch`` sequences before their first measurement (the model's prior, ``P0``)."""
        return AdaptiveState(self.model.prior_state(batch, np.float64), batched(self.P0, batch), np.zeros(batch),
                             self.rule.initial(batch, self.Q0, self.R0))

    gate: float | None = None
    """Chi-square gate level (:meth:`set_gate`); None: no gate."""
    _gate_threshold: float = math.inf

    def set_gate(self, level: float | None) -> None:
        """Skip an update whose NIS ``nu^T S^-1 nu``, with ``S = H P- H^T + R`` from the rule's
        current ``R``, exceeds the chi-square ``level`` quantile (``m`` degrees of freedom), before
        the rule sees it: a gross outlier neither moves the state nor feeds the noise estimates
        (the gate of :meth:`fkn_bench.filters.KalmanFilter.set_gate`). The
        :data:`~fkn_bench.filters.base.GATE_REINITIALISE_AFTER`-th usable measurement in a row
        that is not used (gated out, or a failed update) re-initialises the row's state from it
        (mean from the measurement, ``P0``; the adapted noise is kept): a lost track."""
        self.gate, self._gate_threshold = gate_threshold(level, self.model.measurement_dim)

    def _guarded_update(self, ctx: UpdateContext, noise: Noise) -> tuple[KalmanUpdate, Noise, ArrayB]:
        """The rule's update of ``ctx``'s rows, and ``ok (b,)``: rows whose update failed (the
        innovation covariance not positive definite, an eigen-decomposition that did not
        converge, a non-finite result: the aftermath of gross outliers) are skipped, as an
        unusable measurement is: they keep the prediction and their noise estimates, with a
        zero innovation and an identity innovation covariance. A batch that fails is updated
        row by row, so one row's failure does not stop the others."""
        rule = self.rule
        try:
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                result, new = rule.update(ctx, noise)
            ok = _finite_update(result, new)
        except np.linalg.LinAlgError:
            ok = None
        if ok is not None and ok.all():
            return result, new, ok
        b = ctx.x_pred.shape[0]
        m = ctx.nu.shape[1]
        x, P = ctx.x_pred.copy(), ctx.P_pred.copy()
        S, K = batched(np.eye(m), b), np.zeros((b, x.shape[1], m))
        out = {key: value.copy() for key, value in noise.items()}
        ok = np.zeros(b, dtype=bool)
        for row in range(b):
            one = slice(row, row + 1)
            ctx_row = UpdateContext(ctx.model, ctx.x_pred[one], ctx.P_pred[one], ctx.z[one], ctx.nu[one], ctx.steps[one])
            try:
                with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                    result_row, new_row = rule.update(ctx_row, {key: value[one] for key, value in noise.items()})
            except np.linalg.LinAlgError:
                continue
            if _finite_update(result_row, new_row)[0]:
                ok[row] = True
                x[one], P[one], S[one], K[one] = result_row
                for key, value in out.items():
                    value[one] = new_row[key]
        return KalmanUpdate(x, P, S, K), out, ok

    def steps(self) -> _AdaptiveSteps:
        """The filter's step functions for the one recursion
        (:func:`fkn_bench.filters.recursion.scan` and the online ``advance``)."""
        return _AdaptiveSteps(self)

    def run(self, measurements: ArrayF, mask: ArrayB, *, dt: float) -> AdaptiveResult:
        """Filter a batch of sequences ``measurements (B, T, m)`` with validity ``mask (B, T)``."""
        measurements = np.asarray(measurements, dtype=float)
        mask = np.asarray(mask, dtype=bool)
        m = self.model.measurement_dim
        if measurements.ndim != 3 or measurements.shape[-1] != m:
            raise ValueError(f"measurements must have shape (B, T, {m}) (got {measurements.shape})")
        if mask.shape != measurements.shape[:2]:
            raise ValueError(f"mask must have shape {measurements.shape[:2]} (got {mask.shape})")
        batch, steps, _ = measurements.shape
        z_all, usable = self.model.sanitize(measurements, mask)
        recorder = _AdaptiveSteps(self, steps=steps, batch=batch)
        final = scan(recorder, start_carry(recorder, self.prior(batch), np.zeros(batch, dtype=bool)), z_all, usable, dt)
        buffers = (recorder.means, recorder.covariances, recorder.innovations, recorder.innovation_covs,
                   recorder.prior_means, recorder.updated, recorder.initialised, recorder.r_diag, recorder.q_diag)
        return AdaptiveResult(*(None if a is None else np.swapaxes(a, 0, 1) for a in buffers), final=final.state)


class _AdaptiveSteps:
    """An :class:`AdaptiveKalmanFilter`'s step functions (module docstring of
    :mod:`fkn_bench.filters.recursion`): the EKF prediction with the rule's ``Q``; the gate's
    innovation with the rule's current ``R`` (``S = H P- H^T + R``, before the rule adapts it, so a
    gross outlier neither moves the state nor feeds the noise estimates); the rule's guarded update
    of the accepted rows; initialisation from the measurement with ``P0``, the adapted noise kept.
    With ``steps``, it stores the per-step outputs of :meth:`AdaptiveKalmanFilter.run` (time-major)."""

    def __init__(self, filt: AdaptiveKalmanFilter, *, steps: int = 0, batch: int = 0) -> None:
        self.filter, self.model, self.rule = filt, filt.model, filt.rule
        self.nis_threshold = filt._gate_threshold if filt.gate is not None else math.inf
        if steps:
            n, m = self.model.state_dim, self.model.measurement_dim
            self.means, self.covariances = np.empty((steps, batch, n)), np.empty((steps, batch, n, n))
            self.innovations, self.innovation_covs = np.zeros((steps, batch, m)), np.empty((steps, batch, m, m))
            self.innovation_covs[:] = np.eye(m)
            self.prior_means = np.empty((steps, batch, n))
            self.updated, self.initialised = np.zeros((steps, batch), dtype=bool), np.empty((steps, batch), dtype=bool)
            self.r_diag = np.empty((steps, batch, m))
            self.q_diag = np.empty((steps, batch, n)) if self.rule.adapts_q else None
        self._recording = bool(steps)

    def predict(self, state: AdaptiveState, t: int, dt: float) -> AdaptiveState:
        predicted = ekf_predict(self.model, FilterState(state.x, state.P), self.rule.process_noise(state.noise), dt)
        return AdaptiveState(predicted.mean, predicted.covariance, state.since + 1.0, state.noise)

    def initial(self, state: AdaptiveState, z: ArrayF, t: int) -> AdaptiveState:
        batch = z.shape[0]
        return AdaptiveState(self.model.initial_state(z), batched(self.filter.P0, batch), np.zeros(batch), state.noise)

    def propose(self, state: AdaptiveState, z: ArrayF, rows: ArrayB, t: int) -> Proposal:
        if self.nis_threshold == math.inf:
            return Proposal(None)
        index = np.flatnonzero(rows)
        x_rows, P_rows = state.x[index], state.P[index]
        R = self.rule.measurement_noise({key: value[index] for key, value in state.noise.items()})
        batch, m = state.x.shape[0], self.model.measurement_dim
        nu, S = np.zeros((batch, m)), batched(np.eye(m), batch)
        nu[index] = self.model.align(z[index], x_rows) - self.model.measure(x_rows)
        with np.errstate(over="ignore", invalid="ignore"):
            S[index] = projected_covariance(self.model, P_rows) + R  # H P- H^T + R: the gain's S, without the update
        return Proposal(None, nu, S)

    def commit(self, state: AdaptiveState, z: ArrayF, rows: ArrayB, proposal: Proposal, t: int) -> tuple[Any, ...]:
        """The rule's update of ``rows`` (a failed row keeps its prediction and its noise estimates,
        zero innovation, identity innovation covariance, and counts as not updated)."""
        model = self.model
        x, P, since, noise = state
        batch, m = x.shape[0], model.measurement_dim
        every = bool(rows.all())
        index = slice(None) if every else np.flatnonzero(rows)
        x_rows, P_rows = x[index], P[index]
        z_rows = model.align(z[index], x_rows)
        nu_rows = z_rows - model.measure(x_rows)
        ctx = UpdateContext(model, x_rows, P_rows, z_rows, nu_rows, np.maximum(since[index], 1.0))
        result, noise_rows, ok = self.filter._guarded_update(ctx, {key: value if every else value[index] for key, value in noise.items()})
        used = rows
        if not ok.all():  # skipped rows: no innovation, and they count as not updated
            nu_rows = np.where(ok[:, None], nu_rows, 0.0)
            used = rows.copy()
            used[np.flatnonzero(rows)[~ok]] = False
        if every:
            return AdaptiveState(result.x, result.P, np.where(used, 0.0, since), noise_rows), used, (nu_rows, result.S)
        nu, S = np.zeros((batch, m)), batched(np.eye(m), batch)
        x, P = x.copy(), P.copy()
        x[index], P[index], nu[index], S[index] = result.x, result.P, nu_rows, result.S
        return AdaptiveState(x, P, np.where(used, 0.0, since), _put(noise, index, noise_rows)), used, (nu, S)

    def record(self, t: int, prior: AdaptiveState, state: AdaptiveState, innovation: tuple[ArrayF, ArrayF] | None,
               used: ArrayB | None, initialised: ArrayB) -> None:
        if not self._recording:
            return
        self.means[t], self.covariances[t], self.prior_means[t] = state.x, state.P, prior.x
        if innovation is not None:
            self.innovations[t], self.innovation_covs[t] = innovation
        if used is not None:
            self.updated[t] = used
        self.initialised[t] = initialised
        self.r_diag[t] = np.diagonal(self.rule.measurement_noise(state.noise), axis1=1, axis2=2)
        if self.q_diag is not None:
            self.q_diag[t] = np.diagonal(self.rule.process_noise(state.noise), axis1=1, axis2=2)


def _finite_update(result: KalmanUpdate, noise: Noise) -> ArrayB:
    """``(b,)`` True where an update's mean, covariance, innovation covariance and noise are finite."""
    ok = np.isfinite(result.x).all(1) & np.isfinite(result.P).all((1, 2)) & np.isfinite(result.S).all((1, 2))
    for value in noise.values():
        ok &= np.isfinite(value.reshape(value.shape[0], -1)).all(1)
    return ok


# ---------------------------------------------------------------------------------------------
# the estimator


class AdaptiveEKFEstimator(RecursiveEstimator):
    """An adaptive EKF on the paper's pose-and-twist model as an estimator of the common API.

    Subclasses set ``name``, ``description`` and ``rule_class`` (a :class:`NoiseRule` built from
    its ``knobs``). Keyword-only arguments: the rule's knobs, ``q_std``, ``r_std``, ``p0_std``
    (starting noise and ``P0``; default the paper's manual tuning), ``q_scale`` and ``r_scale``
    (factors in ``(0, 1e6]`` on the starting standard deviations of ``Q`` and ``R``: the initial
    noise as one number each, which a sweep searches), ``adapt`` (``"q"``, ``"r"`` or ``"qr"``:
    what a rule with ``adapt_q``/``adapt_r`` adapts, as one choice), ``gate`` (a chi-square
    innovation gate probability, e.g. 0.999: :meth:`AdaptiveKalmanFilter.set_gate`), ``name`` and
    ``description``.

    ``estimate`` runs every sequence of the batch at once; ``reset``/``step`` run the same
    recursion on one sequence (with the observation-time rules of
    :class:`~fkn_bench.estimators.RecursiveEstimator`). The estimates' ``extras`` hold
    ``r_diag (B, T, 7)``, the adapted ``R``'s diagonal after each step, and for rules that adapt
    ``Q`` ``q_diag (B, T, 13)``.
    """

    rule_class: ClassVar[type[NoiseRule]]

    def __init__(
        self,
        *,
        q_std: Sequence[float] | None = None,
        r_std: Sequence[float] | None = None,
        p0_std: Sequence[float] | None = None,
        q_scale: float = 1.0,
        r_scale: float = 1.0,
        adapt: str | None = None,
        gate: float | None = None,
        name: str | None = None,
        description: str | None = None,
        **knobs: Any,
    ) -> None:
        valid = self.rule_class.knobs
        unknown = sorted(set(knobs) - set(valid))
        if unknown:
            options = valid + ("q_std", "r_std", "p0_std", "q_scale", "r_scale", "adapt", "gate", "name", "description")
            raise ValueError(f"unknown {type(self).__name__} options {unknown}; valid: {sorted(options)}")
        if adapt is not None:  # one categorical for the two booleans (a sweep never tries "neither")
            if "adapt_q" not in valid:
                raise ValueError(f"{type(self).__name__} has no choice of what to adapt (no option adapt)")
            if adapt not in ("q", "r", "qr") or {"adapt_q", "adapt_r"} & set(knobs):
                raise ValueError(f"adapt must be 'q', 'r' or 'qr', given instead of adapt_q/adapt_r (got {adapt!r})")
            knobs = {**knobs, "adapt_q": "q" in adapt, "adapt_r": "r" in adapt}
        self.rule = self.rule_class(**knobs)
        layout = PoseTwistModel().layout
        scales = {"q_scale": check_range("q_scale", q_scale, high=1e6, closed_high=True),
                  "r_scale": check_range("r_scale", r_scale, high=1e6, closed_high=True)}
        # the given deviations are checked as given (an error names the caller's value), then scaled
        given_q = KalmanEstimator._check_std("q_std", q_std, layout.q_default)
        given_r = KalmanEstimator._check_std("r_std", r_std, layout.r_default)
        start_q = None if scales["q_scale"] == 1.0 else [scales["q_scale"] * float(v) for v in given_q]
        start_r = None if scales["r_scale"] == 1.0 else [scales["r_scale"] * float(v) for v in given_r]
        self.filter = AdaptiveKalmanFilter(self.rule, q_std=start_q or q_std, r_std=start_r or r_std, p0_std=p0_std)
        self._stds = {  # the standard deviations and scales given, for to_config
            key: [float(v) for v in value]
            for key, value in (("q_std", q_std), ("r_std", r_std), ("p0_std", p0_std))
            if value is not None
        }
        self._options = {key: float(value) for key, value in scales.items() if value != 1.0}  # for to_config
        self.filter.set_gate(gate)
        if gate is not None:
            self._options["gate"] = float(gate)
        if name is not None:
            self.name = name
        if description is not None:
            self.description = description

    def estimate(self, measurements: ArrayF, mask: ArrayB, dt: float) -> Estimates:
        z, m, step = check_batch_inputs(measurements, mask, dt)
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # overflow: the restart rule
            result = self.filter.run(z, m, dt=step)
            extras = {"r_diag": result.r_diag}
            if result.q_diag is not None:
                extras["q_diag"] = result.q_diag
            estimates = filter_result_to_estimates(result, self.filter, extras=extras)
        return restart_diverged(estimates, lambda zs, ms: self.estimate(zs, ms, step), z, m)

    def _online_prior(self) -> AdaptiveState:
        return self.filter.prior(1)

    def _online_steps(self) -> _AdaptiveSteps:
        return self.filter.steps()

    def _online_report(self, state: AdaptiveState) -> tuple[ArrayF, ArrayF]:
        return state.x[0], state.P[0]

    def to_config(self) -> dict[str, Any]:
        return {**self.rule.config(), **self._stds, **self._options, "name": self.name, "description": self.description}
