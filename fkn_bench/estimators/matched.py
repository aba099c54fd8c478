"""The model-matched references: ``oracle-matched`` (a causal filter) and ``smoother-matched``
(non-causal).

``oracle-matched`` is the multiplicative EKF (:mod:`fkn_bench.filters.mekf`) on the truth's own
model, with the truth's own noise and prior; it is what a filter can do when it knows everything
the scenario states (the yardstick of issue 36 beside the posterior Cramér-Rao bound):

* model: forced dynamics (a constant world-frame rate) -> ``"constant-velocity"``, which the MEKF
  propagates exactly (the exponential of the rate); free dynamics -> ``"rigid-body"`` with the
  scenario's inertia, or ``"rigid-body-ratios"`` (the two log inertia ratios in the state, prior
  mean the nominal inertia's) when the scenario draws each episode's inertia
  (``inertia_error > 0``);
* measurement noise: the truth's, ``R = diag(sigma_att^2 I3, sigma_pos^2 I3)`` (rad, m) with the
  scenario's effective sigmas (the measured attitude is ``exp(e / 2) (x) q``,
  ``e ~ N(0, sigma_att^2 I3)``, world frame: exactly the MEKF's measurement model); with
  ``noise_step_scale != 1`` the truth's noise is that many times larger in the middle third of
  every split (:meth:`fkn_bench.scenarios.Scenario.noise_factor`), and ``estimate`` gives the
  filter that per-step ``R`` on the steps ``[T // 3, 2 T // 3)`` of the ``T`` steps it is given
  (a whole split, as the harness passes them; the online ``step``, which does not know ``T``,
  uses the calm ``R``);
* process noise: none in the truth; :data:`PROCESS_STD` per error component and step keeps the
  recursion healthy (see there);
* initial covariance: the filter initialises its pose from the first measurement, so the
  attitude and position standard deviations are the measurement's; the rate, velocity (and
  ratio) block is the scenario's prior covariance
  (:func:`fkn_bench.scenarios.prior.error_prior`, the ratio block correlated), zero variances
  floored at :data:`PRIOR_FLOOR_STD`;
* outliers (``outlier_fraction > 0``): a chi-square gate at 0.999 (the filter is matched to the
  inlier model; Bar-Shalom, Li & Kirubarajan 2001), sign flips by the MEKF's sign alignment.

It refuses (``ValueError`` naming the reason; the harness reports it as not available) the
scenarios whose prior it cannot match: a rate or velocity prior mean other than zero (the filter
starts from zero rate and velocity: the fixed-truth scenarios ds1, ds2, tumble-*), and torque
bursts (``has_kicks``: a process noise the MEKF's white ``Q`` does not describe).

``smoother-matched`` runs the same filter forward and then the fixed-interval Rauch-Tung-Striebel
smoother backward (:func:`fkn_bench.filters.smoother.smooth_pose`; Rauch, Tung & Striebel, AIAA
Journal 3(8), 1965): each step's estimate uses every measurement of the sequence, later ones
included. It is an offline reference, not a filter: ``causal = False``, its description starts
with ``"non-causal:"``, and ``reset``/``step`` raise.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from fkn_bench.estimators.base import Estimate, Estimates, check_batch_inputs, restart_diverged
from fkn_bench.estimators.kalman import MIN_STD, KalmanEstimator, filter_result_to_estimates
from fkn_bench.estimators.registry import register_estimator
from fkn_bench.filters.pose import state_covariance_from_error, with_unit_quaternion
from fkn_bench.filters.smoother import smooth_pose
from fkn_bench.models.noise import NoiseParameters
from fkn_bench.runtime import torch_threads
from fkn_bench.scenarios import Scenario
from fkn_bench.scenarios.prior import error_prior
from fkn_bench.types import ArrayB, ArrayF

__all__ = ["MatchedEstimator", "MatchedSmoother", "NonCausalError", "PROCESS_STD", "PRIOR_FLOOR_STD", "matched_options",
           "oracle_matched", "smoother_matched"]

PROCESS_STD = MIN_STD
"""Process-noise standard deviation of every error component per step (rad, m, rad/s, m/s; the
log ratios: 1): the truth has none, and this is the smallest the estimator accepts
(:data:`~fkn_bench.estimators.kalman.MIN_STD`, variance 1e-200). It keeps the filter and the
smoother healthy: on spin and free-tumble (10 test episodes of 3000 steps) the RMSE of every
group and the NEES, of the filter and of the smoother, agree to three digits for 1e-100, 1e-12,
1e-9 and 1e-7 (1e-5 starts to change them: spin's NEES 12.6 -> 9.0), as they do for 1e-100 and
1e-9 on tumble-flip, spin-gap100 and free-tumble-flips; every output is finite and every final
covariance positive definite; and both survive the conformance
fuzz (:func:`fkn_bench.estimators.conformance.garbage_measurements`, 250 x 400 steps) without a
warning."""

PRIOR_FLOOR_STD = 10.0 * MIN_STD
"""The standard deviation given to a prior component of zero variance (a component the scenario
fixes, e.g. tumble-flip's zero velocity), in the component's SI unit: the truth's "known
exactly", ten times :data:`~fkn_bench.estimators.kalman.MIN_STD` so that the covariance check's
smallest eigenvalue (1e-198) clears the estimator's 1e-200 with room for rounding. On
tumble-flip (5 test episodes) floors of 1e-99, 1e-30 and 1e-9 give the same attitude RMSE to
every printed digit (filter 0.04626 rad, smoother 0.01743 rad)."""

GATE = 0.999
"""The chi-square gate probability on scenarios with gross outliers."""


def matched_options(scenario: Scenario) -> dict[str, Any]:
    """The :class:`MatchedEstimator` keyword arguments matched to ``scenario`` (module
    docstring); ``ValueError`` naming why for a scenario it cannot match."""
    if scenario.has_kicks:
        raise ValueError(f"{scenario.name} has torque bursts (kick_rate {scenario.kick_rate:g}): a rate process the "
                         "matched MEKF's white process noise does not describe")
    prior = error_prior(scenario)
    if np.any(prior.rate_mean != 0.0):
        raise ValueError(f"{scenario.name}'s prior rate mean is {prior.rate_mean.tolist()} rad/s, not zero: the filter "
                         "starts from zero rate, so it cannot match this prior (a fixed-truth scenario)")
    if np.any(prior.velocity_mean != 0.0):
        raise ValueError(f"{scenario.name}'s prior velocity mean is {prior.velocity_mean.tolist()} m/s, not zero: the "
                         "filter starts from zero velocity, so it cannot match this prior")
    options: dict[str, Any] = {"variant": "mekf"}
    if scenario.dynamics == "free":
        options["model"] = "rigid-body-ratios" if prior.ratios else "rigid-body"
        options["inertia"] = list(scenario.inertia)
    sigma_att, sigma_pos = scenario.sigma_attitude_effective, scenario.sigma_position_effective
    p0 = prior.covariance.copy()
    p0[0:6, :] = 0.0
    p0[:, 0:6] = 0.0
    p0[0:6, 0:6] = np.diag([sigma_att**2] * 3 + [sigma_pos**2] * 3)
    zero = np.diag(p0) == 0.0
    p0[zero, zero] = PRIOR_FLOOR_STD**2
    n = p0.shape[0]
    options.update(q_std=[PROCESS_STD] * n, r_std=[sigma_att] * 3 + [sigma_pos] * 3, p0_cov=p0.tolist())
    if scenario.outlier_fraction > 0:
        options["gate"] = GATE
    if scenario.noise_step_scale != 1.0:
        options["noise_step_scale"] = scenario.noise_step_scale
    return options


class MatchedEstimator(KalmanEstimator):
    """A :class:`~fkn_bench.estimators.kalman.KalmanEstimator` with the truth's measurement-noise
    schedule: ``noise_step_scale`` multiplies ``R``'s standard deviations on the middle third
    ``[T // 3, 2 T // 3)`` of the ``T`` steps ``estimate`` is given (module docstring); the
    online ``step`` uses the calm ``R``. Everything else is the Kalman estimator's."""

    def __init__(self, *, noise_step_scale: float = 1.0, **options: Any) -> None:
        super().__init__(**options)
        scale = float(noise_step_scale)
        if not (np.isfinite(scale) and scale > 0):
            raise ValueError(f"noise_step_scale must be a finite number > 0 (got {noise_step_scale!r})")
        self.noise_step_scale = scale

    CONFIG_KEYS = KalmanEstimator.CONFIG_KEYS | {"noise_step_scale"}

    def to_config(self) -> dict[str, Any]:
        config = super().to_config()
        if self.noise_step_scale != 1.0:
            config["noise_step_scale"] = self.noise_step_scale
        return config

    def noise_schedule(self, steps: int, offset: int = 0) -> NoiseParameters:
        """``Q``, ``R``, ``P0`` for steps ``offset .. offset + steps - 1`` of a sequence of
        ``offset + steps`` (``R`` per step, ``(1, steps, 6, 6)``, where ``noise_step_scale != 1``)."""
        noise = self.noise_parameters()
        if self.noise_step_scale == 1.0:
            return noise
        total = offset + steps
        index = np.arange(offset, total)
        factor = np.where((index >= total // 3) & (index < 2 * total // 3), self.noise_step_scale, 1.0)
        R = torch.from_numpy(factor**2)[None, :, None, None] * noise.measurement
        return NoiseParameters(noise.process, R, noise.initial)

    def estimate(self, measurements: ArrayF, mask: ArrayB, dt: float) -> Estimates:
        z, m, step = check_batch_inputs(measurements, mask, dt)
        return self._estimate(z, m, step, z.shape[1], full=False)

    def _estimate(self, z: ArrayF, m: ArrayB, dt: float, total: int, *, full: bool) -> Estimates:
        """``estimate`` of the last ``z.shape[1]`` steps of a sequence of ``total`` (a restart
        refilters a tail); ``full``: also ``extras["state"] (B, T, n)`` and
        ``extras["state_covariance"] (B, T, n - 1, n - 1)``, the filter's own (with the ratios)."""
        noise = self.noise_schedule(z.shape[1], total - z.shape[1])
        with torch.no_grad(), torch_threads(), np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            result = self.filter.run(noise, torch.from_numpy(z), torch.from_numpy(m), dt=dt)
            extras = {"state": result.means.numpy(), "state_covariance": result.covariances.numpy()} if full else None
            estimates = filter_result_to_estimates(result, self.filter, extras=extras)
        return restart_diverged(estimates, lambda zs, ms: self._estimate(zs, ms, dt, total, full=full), z, m)


class NonCausalError(RuntimeError):
    """An online step asked of an estimator that needs the whole sequence (a smoother)."""


class MatchedSmoother(MatchedEstimator):
    """The fixed-interval RTS smoother of :class:`MatchedEstimator` (module docstring): batch
    ``estimate`` only. Reports the smoothed means and 12x12 error covariances (and the 13x13
    state covariances), the forward filter's ``innovation_mask`` and ``initialised``, no
    innovations (the smoother has none of its own), and ``extras["inertia_ratios"]`` smoothed
    where the model carries them.

    Segments (:func:`fkn_bench.filters.smoother.rts_smooth`): a step links to the next when
    both are initialised, the next did not restart (``extras["restarted"]``) and its covariance
    is not the filter's ``P0`` bit for bit (the mark of an initialisation or of a lost-track
    re-initialisation, :data:`fkn_bench.filters.recursion.GATE_REINITIALISE_AFTER`). A sequence
    whose smoothed values are not all finite keeps its filtered ones."""

    causal = False

    def reset(self, *, dt: float) -> None:
        raise NonCausalError(f"{self.name} is a non-causal smoother: it needs the whole sequence (estimate), "
                             "it has no online reset()/step()")

    def step(self, observation: Any) -> Estimate:
        raise NonCausalError(f"{self.name} is a non-causal smoother: it needs the whole sequence (estimate), "
                             "it has no online step()")

    def estimate(self, measurements: ArrayF, mask: ArrayB, dt: float) -> Estimates:
        z, m, step = check_batch_inputs(measurements, mask, dt)
        forward = self._estimate(z, m, step, z.shape[1], full=True)
        extras = dict(forward.extras)
        state, covariance = extras.pop("state"), extras.pop("state_covariance")
        initialised = forward.initialised
        P0 = self._numpy_noise[2]
        fresh = (covariance == P0).all(axis=(-2, -1))
        restarted = extras.get("restarted", np.zeros_like(initialised))
        linked = initialised[:, :-1] & initialised[:, 1:] & ~restarted[:, 1:] & ~fresh[:, 1:]
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            means, error_covariances = smooth_pose(self.filter.model, state, covariance, self._numpy_noise[0], step,
                                                   linked=linked)
        bad = ~(np.isfinite(means).all(axis=(1, 2)) & np.isfinite(error_covariances).all(axis=(1, 2, 3)))
        means[bad], error_covariances[bad] = state[bad], covariance[bad]
        extra = means.shape[-1] - 13
        if extra:
            extras["inertia_ratios"] = means[..., 13:].copy()
            error_covariances = error_covariances[..., :12, :12]
        means = with_unit_quaternion(means[..., :13])
        return Estimates(
            means=means,
            covariances=state_covariance_from_error(means[..., :4], error_covariances),
            error_covariances=np.ascontiguousarray(error_covariances),
            innovation_mask=forward.innovation_mask,
            initialised=initialised,
            extras=extras,
        )


def _build(cls: type[MatchedEstimator], name: str, what: str, scenario: Scenario | None, options: dict[str, Any]) -> Any:
    if scenario is None:
        raise ValueError(f"{name} needs the scenario whose model, noise and prior it is matched to")
    matched = matched_options(scenario)
    matched.update(options)
    matched.setdefault("name", name)
    matched.setdefault("description", f"{what} matched to {scenario.name} ({matched.get('model', 'constant-velocity')})")
    return cls(**matched)


def oracle_matched(scenario: Scenario | None = None, **options: Any) -> MatchedEstimator:
    """The model-matched MEKF for ``scenario`` (module docstring); ``options`` override the
    matched keyword arguments (:func:`matched_options`)."""
    return _build(MatchedEstimator, "oracle-matched", "MEKF on the truth's model, noise and prior,", scenario, options)


def smoother_matched(scenario: Scenario | None = None, **options: Any) -> MatchedSmoother:
    """The RTS smoother of the model-matched MEKF for ``scenario`` (non-causal)."""
    return _build(MatchedSmoother, "smoother-matched", "non-causal: RTS smoother of the MEKF on the truth's model, noise and prior,",
                  scenario, options)


register_estimator("oracle-matched", oracle_matched,
                   description="MEKF on the truth's model, noise and prior (model-matched oracle; prior families only)")
register_estimator("smoother-matched", smoother_matched,
                   description="non-causal: fixed-interval RTS smoother of the model-matched MEKF (offline reference)")
