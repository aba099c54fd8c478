"""Kalman-filter estimators with constant noise parameters (any variant of the filter core).

:class:`KalmanEstimator` runs ``ekf``, ``ukf`` or ``mekf`` with fixed standard deviations of
``Q``, ``R`` and ``P0`` (in the variant's layout). Batch ``estimate`` runs the torch core; online
``step`` runs the lean numpy EKF (:mod:`fkn_bench.filters.online_ekf`) for the EKF and the torch
core one step at a time for the other variants. Both paths follow the same rules and agree to
1e-12.

Online time handling: steps are taken ``dt`` apart. When an observation carries a ``time``, it
must increase; an interval that differs from ``dt`` by more than 1e-6 s is predicted over its
actual length.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from fkn_bench.estimators.base import Estimate, Estimates, Estimator, check_batch_inputs, check_dt, parse_observation
from fkn_bench.filters import VARIANTS, FilterState, KalmanFilter, NoiseParameters, make_filter
from fkn_bench.filters import online_ekf
from fkn_bench.filters.base import FilterResult
from fkn_bench.filters.pose import (
    error_covariance_from_state,
    pose_innovation,
    state_covariance_from_error,
    with_unit_quaternion,
)
from fkn_bench.linalg import symmetrize
from fkn_bench.runtime import torch_threads
from fkn_bench.types import ArrayB, ArrayF

__all__ = ["KalmanEstimator", "filter_result_to_estimates"]

_TIME_TOLERANCE = 1e-6


@dataclass(frozen=True)
class _OnlineState:
    time: float
    x: ArrayF
    P: ArrayF
    initialised: bool


def filter_result_to_estimates(result: FilterResult, variant: KalmanFilter) -> Estimates:
    """Convert a torch :class:`FilterResult` of a pose filter to numpy :class:`Estimates`."""
    means = with_unit_quaternion(result.means.detach().numpy())
    q = means[..., :4]
    covariances = error_covariances = None
    if result.covariances is not None:
        native = result.covariances.detach().numpy()
        if variant.covariance_dim == 12:
            error_covariances, covariances = native, state_covariance_from_error(q, native)
        else:
            covariances, error_covariances = native, error_covariance_from_state(q, native)
    innovations = innovation_covariances = None
    if result.innovations is not None and result.innovation_covariances is not None:
        nu = result.innovations.detach().numpy()
        S = result.innovation_covariances.detach().numpy()
        if variant.innovation_dim == 6:
            innovations, innovation_covariances = nu, S
        else:
            assert result.prior_means is not None
            innovations, innovation_covariances = pose_innovation(result.prior_means.detach().numpy()[..., :4], nu, S)
    return Estimates(
        means=means,
        covariances=covariances,
        error_covariances=error_covariances,
        innovations=innovations,
        innovation_covariances=innovation_covariances,
        innovation_mask=result.updated.numpy(),
        initialised=result.initialised.numpy(),
    )


class KalmanEstimator(Estimator):
    """A filter variant with constant noise parameters.

    Keyword-only arguments:
        variant: ``"ekf"``, ``"ukf"`` or ``"mekf"``.
        q_std, r_std, p0_std: standard deviations in the variant's layout (default: its manual
            tuning; see :data:`fkn_bench.filters.models.PAPER_MANUAL_LAYOUT` and
            :data:`fkn_bench.filters.MEKF_MANUAL_LAYOUT`).
        q_cov, r_cov, p0_cov: full covariance matrices instead (symmetric positive definite);
            give either the standard deviations or the matrix of an entry, not both.
        name, description: registry name and one-line description.
    """

    def __init__(
        self,
        *,
        variant: str = "ekf",
        q_std: Sequence[float] | None = None,
        r_std: Sequence[float] | None = None,
        p0_std: Sequence[float] | None = None,
        q_cov: Sequence[Sequence[float]] | None = None,
        r_cov: Sequence[Sequence[float]] | None = None,
        p0_cov: Sequence[Sequence[float]] | None = None,
        name: str = "kalman",
        description: str = "",
    ) -> None:
        if variant not in VARIANTS:
            raise ValueError(f"unknown filter variant {variant!r}; valid variants: {', '.join(VARIANTS)}")
        self.variant_name = variant
        self.filter = make_filter(variant)
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
        self._numpy_noise = tuple(matrices)
        self.name = name
        self.description = description
        self._dt: float | None = None
        self._online: _OnlineState | None = None

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
        array = np.array(default if values is None else values, dtype=float)
        if array.shape != (len(default),):
            raise ValueError(f"{name} needs {len(default)} values (got shape {array.shape})")
        if not np.all(np.isfinite(array)) or np.any(array <= 0):
            raise ValueError(f"{name} values must be finite and > 0 (got {array.tolist()})")
        return array

    @staticmethod
    def _check_cov(name: str, values: Sequence[Sequence[float]], dim: int) -> ArrayF:
        array = np.array(values, dtype=float)
        if array.shape != (dim, dim):
            raise ValueError(f"{name} must be a {dim}x{dim} matrix (got shape {array.shape})")
        if not np.all(np.isfinite(array)) or not np.allclose(array, array.T, rtol=1e-10, atol=1e-14):
            raise ValueError(f"{name} must be finite and symmetric")
        symmetric = symmetrize(array)
        if np.linalg.eigvalsh(symmetric).min() <= 0:
            raise ValueError(f"{name} must be positive definite")
        return symmetric

    # ------------------------------------------------------------------ batch
    def noise_parameters(self) -> NoiseParameters:
        """The constant ``Q``, ``R``, ``P0`` as torch tensors."""
        return NoiseParameters(*(torch.from_numpy(m.copy()) for m in self._numpy_noise))

    def estimate(self, measurements: ArrayF, mask: ArrayB, dt: float) -> Estimates:
        z, m, step = check_batch_inputs(measurements, mask, dt)
        with torch.no_grad(), torch_threads():
            result = self.filter.run(self.noise_parameters(), torch.from_numpy(z), torch.from_numpy(m), dt=step)
        return filter_result_to_estimates(result, self.filter)

    # ------------------------------------------------------------------ online
    def reset(self, *, dt: float) -> None:
        self._dt = check_dt(dt)
        self._online = None

    def _predict(self, x: ArrayF, P: ArrayF, dt: float) -> tuple[ArrayF, ArrayF]:
        Q = self._numpy_noise[0]
        if self.variant_name == "ekf":
            return online_ekf.predict(x, P, Q, dt)
        with torch.no_grad():  # torch.tensor copies: P is shared read-only with the last Estimate
            state = self.filter.predict(FilterState(torch.tensor(x)[None], torch.tensor(P)[None]), torch.tensor(Q), dt)
        return state.mean[0].numpy(), state.covariance[0].numpy()  # symmetrised by predict

    def _update(self, x: ArrayF, P: ArrayF, z: ArrayF) -> tuple[ArrayF, ArrayF]:
        R = self._numpy_noise[1]
        if self.variant_name == "ekf":
            x, P, _, _ = online_ekf.update(x, P, z, R)
            return x, P
        with torch.no_grad():
            state, _, _ = self.filter.update(
                FilterState(torch.tensor(x)[None], torch.tensor(P)[None]), torch.tensor(z)[None], torch.tensor(R)
            )
        return state.mean[0].numpy(), state.covariance[0].numpy()  # symmetrised by update

    def step(self, observation: Any) -> Estimate:
        if self._dt is None:
            raise RuntimeError("call reset(dt=...) before step()")
        pose, time = parse_observation(observation)
        z = None if pose is None else online_ekf.sanitize_measurement(pose)
        previous = self._online
        if previous is None:
            now = 0.0 if time is None else time
            x = np.zeros(13)
            x[0] = 1.0
            P = self._numpy_noise[2]
            initialised = False
        else:
            now = previous.time + self._dt if time is None else time
            interval = now - previous.time
            if interval <= 0:
                raise ValueError(f"observation time {now} does not increase (previous {previous.time})")
            if abs(interval - self._dt) <= _TIME_TOLERANCE:
                interval = self._dt
            x, P = self._predict(previous.x, previous.P, interval)
            initialised = previous.initialised
        updated = False
        if z is not None:
            if not initialised:
                x, P, initialised = online_ekf.initial_state(z), self._numpy_noise[2], True
            else:
                x, P = self._update(x, P, z)
                updated = True
        # x and P are fresh arrays (the filter functions are pure): share P read-only
        self._online = _OnlineState(now, x, P, initialised)
        mean = x.copy()
        mean[0:4] /= math.sqrt(mean[0:4] @ mean[0:4])
        return Estimate(time=now, mean=mean, native_covariance=P, initialised=initialised, updated=updated)

    # ------------------------------------------------------------------ config
    def to_config(self) -> dict[str, Any]:
        config: dict[str, Any] = {"variant": self.variant_name}
        for index, entry in enumerate(("q", "r", "p0")):
            matrix = self._numpy_noise[index]
            if self._given[entry] == "cov":
                config[f"{entry}_cov"] = matrix.tolist()
            else:
                config[f"{entry}_std"] = np.sqrt(np.diag(matrix)).tolist()
        config.update(name=self.name, description=self.description)
        return config

    @classmethod
    def from_config(cls, config: Mapping[str, Any]) -> KalmanEstimator:
        known = {"variant", "q_std", "r_std", "p0_std", "q_cov", "r_cov", "p0_cov", "name", "description"}
        unknown = sorted(set(config) - known)
        if unknown:
            raise ValueError(f"unknown KalmanEstimator config keys {unknown}; valid: {sorted(known)}")
        return cls(**dict(config))
