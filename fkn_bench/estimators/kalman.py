"""Kalman-filter estimators with constant noise parameters (any variant of the filter core).

:class:`KalmanEstimator` runs ``ekf``, ``ukf`` or ``mekf`` with fixed standard deviations of
``Q``, ``R`` and ``P0`` (in the variant's layout). Batch ``estimate`` runs the variant on torch tensors;
online ``step`` runs the same step functions on numpy arrays of one sequence (the shared online
recursion of :class:`~fkn_bench.estimators.base.RecursiveEstimator`: time handling,
initialisation, skipped updates). Both paths agree to 1e-12.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch

from fkn_bench.estimators.base import Estimates, RecursiveEstimator, check_batch_inputs, restart_diverged
from fkn_bench.filters import VARIANTS, make_filter
from fkn_bench.filters.pose import (
    error_covariance_from_state,
    pose_innovation,
    state_covariance_from_error,
    with_unit_quaternion,
)
from fkn_bench.estimators.message_noise import MEASUREMENT_NOISE_MODES, message_noise
from fkn_bench.linalg import symmetrize
from fkn_bench.models.noise import NoiseParameters
from fkn_bench.models.registry import DEFAULT_MODEL, make_model, model_spec
from fkn_bench.runtime import torch_threads
from fkn_bench.types import ArrayB, ArrayF

__all__ = ["KalmanEstimator", "MAX_STD", "MIN_STD", "filter_result_to_estimates"]

def filter_result_to_estimates(result: Any, variant: Any, *, extras: Mapping[str, ArrayF] | None = None) -> Estimates:
    """Convert the result of a pose filter's ``run`` (a torch :class:`FilterResult`, or the numpy
    result of an adaptive filter: the same fields) to numpy :class:`Estimates`; ``variant`` gives
    ``covariance_dim`` (13 or 12) and ``innovation_dim`` (7 or 6)."""
    numpy = lambda a: None if a is None else a.detach().numpy() if hasattr(a, "detach") else a  # noqa: E731
    states = numpy(result.means)
    extras = dict(extras or {})
    native = numpy(result.covariances)
    extra = states.shape[-1] - 13
    if extra:  # an augmented state (inertia ratios, last): the pose and twist are reported
        extras.setdefault("inertia_ratios", states[..., 13:].copy())
        states = states[..., :13]
        native = None if native is None else native[..., : native.shape[-1] - extra, : native.shape[-1] - extra]
    means = with_unit_quaternion(states)
    q = means[..., :4]
    covariances = error_covariances = native
    if native is not None:
        if native.shape[-1] == 12:  # the multiplicative EKF's error covariance
            covariances = state_covariance_from_error(q, native)
        else:
            error_covariances = error_covariance_from_state(q, native)
    innovations, innovation_covariances = numpy(result.innovations), numpy(result.innovation_covariances)
    if innovations is not None and variant.innovation_dim != 6:
        innovations, innovation_covariances = pose_innovation(numpy(result.prior_means)[..., :4], innovations, innovation_covariances)
    return Estimates(
        means=means,
        covariances=covariances,
        error_covariances=error_covariances,
        innovations=innovations,
        innovation_covariances=innovation_covariances,
        innovation_mask=numpy(result.updated),
        initialised=numpy(result.initialised),
        extras=extras,
    )


MIN_STD = 1e-100
"""The smallest noise standard deviation an estimator accepts (in the component's SI unit): its
square, 1e-200, is still a normal float64 (a tuned filter may drive a component's process noise
to ~1e-21: the committed nll-tuned-ekf does); smaller ones would underflow to zero."""

MAX_STD = 1e6
"""The largest noise standard deviation an estimator accepts: a million metres, radians or
metres per second is no noise model of this problem, and a larger one's square (``1e160``
squares to ``inf``) would put infinities, then NaN, into the filter."""


class KalmanEstimator(RecursiveEstimator):
    """A filter variant with constant noise parameters.

    Keyword-only arguments:
        variant: ``"ekf"``, ``"ukf"`` or ``"mekf"``.
        model: the process model (:func:`fkn_bench.models.model_names`): ``"constant-velocity"``
            (the paper's), ``"rigid-body"`` (torque free, known ``inertia``) or
            ``"rigid-body-ratios"`` (inertia ratios estimated; ``inertia`` is their prior mean).
            The rigid-body models run on the EKF and the UKF; with estimated ratios ``q_std`` and
            ``p0_std`` have two more entries (the log ratios) and ``Estimates.extras`` holds
            ``inertia_ratios`` ``(B, T, 2)``.
        inertia: principal moments ``(Jx, Jy, Jz)`` in kg m^2 (rigid-body models only).
        q_std, r_std, p0_std: standard deviations in the variant's layout (default: its manual
            tuning; see :data:`fkn_bench.models.pose_twist.PAPER_MANUAL_LAYOUT` and
            :data:`fkn_bench.filters.MEKF_MANUAL_LAYOUT`).
        q_cov, r_cov, p0_cov: full covariance matrices instead (symmetric positive definite);
            give either the standard deviations or the matrix of an entry, not both.
        gate: chi-square innovation gate probability, e.g. 0.999 (None: no gate): an update
            whose normalised innovation squared exceeds that quantile is skipped
            (:meth:`~fkn_bench.filters.KalmanFilter.set_gate`), in ``estimate`` and ``step`` alike.
        measurement_noise: ``"default"`` (``R`` above at every step) or ``"message"``: in
            ``estimate``, each step's ``R`` from the covariance its measurement states
            (``measurement_covariances``; :mod:`fkn_bench.estimators.message_noise`: validated, a
            step without a usable one takes ``R``, counted in ``Estimates.extras
            ["measurement_noise_defaults"]``); the online ``step`` uses ``R``.
        name, description: registry name and one-line description.
    """

    def __init__(
        self,
        *,
        variant: str = "ekf",
        model: str = DEFAULT_MODEL,
        inertia: Sequence[float] | None = None,
        q_std: Sequence[float] | None = None,
        r_std: Sequence[float] | None = None,
        p0_std: Sequence[float] | None = None,
        q_cov: Sequence[Sequence[float]] | None = None,
        r_cov: Sequence[Sequence[float]] | None = None,
        p0_cov: Sequence[Sequence[float]] | None = None,
        gate: float | None = None,
        measurement_noise: str = "default",
        name: str = "kalman",
        description: str = "",
    ) -> None:
        if measurement_noise not in MEASUREMENT_NOISE_MODES:
            raise ValueError(f"measurement_noise must be one of {', '.join(MEASUREMENT_NOISE_MODES)} "
                             f"(got {measurement_noise!r})")
        self.measurement_noise = measurement_noise
        if variant not in VARIANTS:
            raise ValueError(f"unknown filter variant {variant!r}; valid variants: {', '.join(VARIANTS)}")
        model_spec(model)  # (ValueError naming the valid models)
        self.variant_name, self.model_name = variant, model
        self.inertia = None if inertia is None else tuple(float(v) for v in inertia)
        self.filter = make_filter(variant, model=make_model(model, inertia=self.inertia))
        self.filter.set_gate(gate)
        layout = self.filter.layout
        matrices = []
        self._given: dict[str, str] = {}
        for entry, std, cov, default in (
            ("q", q_std, q_cov, layout.q_default),
            ("r", r_std, r_cov, layout.r_default),
            ("p0", p0_std, p0_cov, layout.p0_default),
        ):
            if std is not None and cov is not None:
                raise ValueError(f"give either {entry}_std or {entry}_cov, not both")
            if cov is not None:
                matrices.append(self._check_cov(f"{entry}_cov", cov, len(default)))
                self._given[entry] = "cov"
            else:
                matrices.append(np.diag(np.square(self._check_std(f"{entry}_std", std, default))))
                self._given[entry] = "std"
        self._numpy_noise = self._online_noise = tuple(matrices)
        self.name = name
        self.description = description

    @property
    def q_std(self) -> ArrayF:
        """Standard deviations of ``Q`` (square roots of its diagonal)."""
        return np.sqrt(np.diag(self._numpy_noise[0]))

    @property
    def r_std(self) -> ArrayF:
        return np.sqrt(np.diag(self._numpy_noise[1]))

    @property
    def p0_std(self) -> ArrayF:
        return np.sqrt(np.diag(self._numpy_noise[2]))

    @staticmethod
    def _check_std(name: str, values: Sequence[float] | None, default: Sequence[float]) -> ArrayF:
        try:
            array = np.array(default if values is None else values, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"{name} must be {len(default)} numbers (got {values!r})") from None
        if array.shape != (len(default),):
            raise ValueError(f"{name} needs {len(default)} values (got shape {array.shape})")
        outside = ~((array >= MIN_STD) & (array <= MAX_STD))  # also NaN
        if outside.any():
            index = int(np.flatnonzero(outside)[0])
            raise ValueError(
                f"{name}[{index}] = {float(array[index])!r} is outside [{MIN_STD:g}, {MAX_STD:g}] "
                "(standard deviations in the component's SI unit; see fkn_bench.estimators.kalman.MAX_STD)"
            )
        return array

    @staticmethod
    def _check_cov(name: str, values: Sequence[Sequence[float]], dim: int) -> ArrayF:
        try:
            array = np.array(values, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"{name} must be a {dim}x{dim} matrix of numbers") from None
        if array.shape != (dim, dim):
            raise ValueError(f"{name} must be a {dim}x{dim} matrix (got shape {array.shape})")
        if not np.all(np.isfinite(array)) or not np.allclose(array, array.T, rtol=1e-10, atol=1e-14):
            raise ValueError(f"{name} must be finite and symmetric")
        symmetric = symmetrize(array)
        eigenvalues = np.linalg.eigvalsh(symmetric)
        if eigenvalues.min() <= 0:
            raise ValueError(f"{name} must be positive definite")
        if eigenvalues.min() < MIN_STD**2 or eigenvalues.max() > MAX_STD**2:
            raise ValueError(f"{name}'s eigenvalues must lie in [{MIN_STD**2:g}, {MAX_STD**2:g}] "
                             f"(got {eigenvalues.min():g} to {eigenvalues.max():g})")
        return symmetric

    # ------------------------------------------------------------------ batch
    def noise_parameters(self) -> NoiseParameters:
        """The constant ``Q``, ``R``, ``P0`` as torch tensors."""
        return NoiseParameters(*(torch.from_numpy(m.copy()) for m in self._numpy_noise))

    @property
    def uses_measurement_covariances(self) -> bool:
        """Whether ``estimate`` takes ``measurement_covariances`` (``measurement_noise="message"``)."""
        return self.measurement_noise == "message"

    def estimate(self, measurements: ArrayF, mask: ArrayB, dt: float, *,
                 measurement_covariances: ArrayF | None = None) -> Estimates:
        """Filter whole sequences; with ``measurement_noise="message"``, ``measurement_covariances``
        ``(B, T, 6, 6)`` (:attr:`fkn_bench.envs.Episodes.measurement_covariances`) give each step's
        ``R``."""
        z, m, step = check_batch_inputs(measurements, mask, dt)
        noise, extras = self.noise_parameters(), None
        if self.uses_measurement_covariances:
            R, defaults = message_noise(measurement_covariances, z, m, self._numpy_noise[1])
            noise = NoiseParameters(noise.process, torch.from_numpy(R), noise.initial)
            extras = {"measurement_noise_defaults": defaults}
        # overflow in a diverging sequence is handled by the restart rule (no warning)
        with torch.no_grad(), torch_threads(), np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            result = self.filter.run(noise, torch.from_numpy(z), torch.from_numpy(m), dt=step)
            estimates = filter_result_to_estimates(result, self.filter, extras=extras)
        if not self.uses_measurement_covariances or measurement_covariances is None:
            return restart_diverged(estimates, lambda zs, ms: self.estimate(zs, ms, step), z, m)
        return restart_diverged(estimates, lambda zs, ms, cs: self.estimate(zs, ms, step, measurement_covariances=cs),
                                z, m, per_step_inputs=(np.asarray(measurement_covariances, dtype=float),))

    def _online_report(self, state: Any) -> tuple[ArrayF, ArrayF]:
        mean, covariance = state.mean[0], state.covariance[0]
        extra = mean.shape[0] - 13  # augmented states (inertia ratios, last) are not reported
        return (mean[:13], covariance[:-extra, :-extra]) if extra else (mean, covariance)

    # ------------------------------------------------------------------ config
    def to_config(self) -> dict[str, Any]:
        config: dict[str, Any] = {"variant": self.variant_name}
        if self.model_name != DEFAULT_MODEL:
            config.update(model=self.model_name, inertia=None if self.inertia is None else list(self.inertia))
        for index, entry in enumerate(("q", "r", "p0")):
            matrix = self._numpy_noise[index]
            if self._given[entry] == "cov":
                config[f"{entry}_cov"] = matrix.tolist()
            else:
                config[f"{entry}_std"] = np.sqrt(np.diag(matrix)).tolist()
        if self.filter.gate is not None:
            config["gate"] = self.filter.gate
        if self.measurement_noise != "default":
            config["measurement_noise"] = self.measurement_noise
        config.update(name=self.name, description=self.description)
        return config

    CONFIG_KEYS = frozenset({"variant", "model", "inertia", "q_std", "r_std", "p0_std", "q_cov", "r_cov", "p0_cov", "gate",
                             "measurement_noise", "name", "description"})
    """Keys of :meth:`to_config` (subclasses add theirs)."""

    @classmethod
    def from_config(cls, config: Mapping[str, Any]) -> KalmanEstimator:
        unknown = sorted(set(config) - cls.CONFIG_KEYS)
        if unknown:
            raise ValueError(f"unknown {cls.__name__} config keys {unknown}; valid: {sorted(cls.CONFIG_KEYS)}")
        return cls(**dict(config))
