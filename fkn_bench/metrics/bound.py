"""The posterior Cramér-Rao bound (PCRB): the smallest mean-square error any estimator can reach.

For a state ``x_k`` observed through ``y_k = h(x_k) + v_k`` and moving by ``x_{k+1} = f(x_k) +
w_k``, every estimator's error covariance is at least ``J_k^-1``, the inverse of the Bayesian
information matrix, which obeys (Tichavský, Muravchik & Nehorai, "Posterior Cramér-Rao bounds for
discrete-time nonlinear filtering", IEEE TSP 46(5), 1998, eq. 21)::

    J_{k+1} = D22 - D21 (J_k + D11)^-1 D12,    J_0 = P_0^-1 (the prior's information)
    D11 = F^T Q^-1 F,  D12 = D21^T = -F^T Q^-1,  D22 = Q^-1 + H^T R^-1 H   (H^T R^-1 H at measured steps)

With ``F`` and ``H`` the Jacobians at the true states of an episode (the bound of that sample path,
as Ristic, Arulampalam & Gordon, *Beyond the Kalman Filter*, Artech House 2004, section 4.2, and
Stone Soup's PCRB metric evaluate it), the matrix inversion lemma turns this into the Riccati
recursion of a Kalman filter linearised along the truth, written here in covariance form so that a
singular ``Q`` (deterministic truths, the general case here: ``Q = 0`` but for torque bursts) and a
singular prior (a component the scenario fixes) need no inverse::

    B_{k+1|k} = F_k B_k F_k^T + Q_k,   B_k = (I - K H) B_{k|k-1} (I - K H)^T + K R_k K^T  (Joseph)

On a linear-Gaussian model this is the Kalman filter's covariance (the tests hold it to rounding).

What the bound uses of a scenario (:class:`~fkn_bench.scenarios.Scenario`):

* the truth model, written once in :mod:`fkn_bench.models`: forced rotation is the constant
  world-frame rate (:class:`~fkn_bench.models.pose_twist.PoseTwistModel`, exact exponential), a
  free tumble the torque-free rigid body (:class:`~fkn_bench.models.rigid_body.RigidBodyModel`
  with the episode's own log inertia ratios in the state, so the inertia is either known, a zero
  prior variance, or unknown with the scenario's prior); the error-state transition
  ``F`` of either is :func:`fkn_bench.models.error_state.error_transition` (attitude as a
  3-dimensional world-frame error, ``q_true = exp(dtheta / 2) (x) q``);
* torque bursts (forced rotation only): the rate offset decays by ``a = exp(-dt / kick_decay)``
  per step, so the rate block of ``F`` is ``a I``, and a step inside a burst adds ``Q =
  kick_sigma^2 I`` to the rate; the bound knows where the bursts are (a genie: still a lower
  bound for an estimator that does not);
* the stated prior (:func:`fkn_bench.scenarios.prior.error_prior`: its exact second moments; the
  bound is that of the Gaussian prior with the same spread);
* the measurement noise: ``H = [I6 0]`` (the measured attitude is ``exp(e / 2) (x) q`` with ``e ~
  N(0, sigma_att^2 I3)``, world frame, so ``H`` is exact), ``R_k = diag(sigma_att^2 I3,
  sigma_pos^2 I3)`` times the scenario's noise factor squared at step ``k``
  (:meth:`Scenario.noise_factor`);
* each episode's actual measurement schedule (the measurements that exist: the period, dropout,
  bursts of gaps). Outliers and sign flips are not modelled: the bound is that of the inlier
  model (every measurement that exists is treated as an inlier), as the report says;
* a time-split scenario (the paper's: train, val and test are pieces of each episode) scores the
  test piece with estimators that start there: the bound propagates the prior without
  measurements from step 0 to the piece's start (a forced rotation: its rate offsets' bursts
  included), then runs over the piece. A free tumble's error grows exponentially over thousands of
  steps near a flip, where a linearised propagation means nothing: there the bound starts at the
  piece with the stated spreads (:func:`~fkn_bench.scenarios.prior.error_prior`), an isotropic
  rate's second moment taken from the truth's rate at the piece's first step (a fixed body rate
  under a uniform attitude: its magnitude is the prior's, its direction uniform).

Reported on the scale of every RMSE column (:mod:`fkn_bench.metrics.accuracy`): per episode and
over the scored window ``[cut, T)`` of the split, the group bounds ``sqrt(mean_k tr B_k[g])``
(attitude in degrees: ``E[|dtheta|^2] >= tr B[dtheta]``; position m, rate rad/s, velocity m/s);
the 13 component bounds, the quaternion's from ``dq = -1/2 Theta(q) dtheta`` (the component error
of a sign-aligned estimate, to first order); and the 13-state bound ``sqrt(mean_k mean_i
B_k[i, i])`` over those 13. Over episodes: the mean and its Monte-Carlo standard error
(:class:`BoundSummary`). ``efficiency = bound / RMSE`` (1.0 is the best possible).

Cost: one recursion per episode, all episodes of a call batched; the Jacobians of a chunk of steps
in one vectorised call of the model.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from fkn_bench.geometry import quaternion as quat
from fkn_bench.metrics.errors import GROUP_UNITS, GROUPS
from fkn_bench.types import ArrayB, ArrayF, Bool, Float

__all__ = ["Bound", "BoundSummary", "posterior_bound", "covariance_recursion", "CHUNK_STEPS", "efficiency"]

CHUNK_STEPS = 512
"""Steps whose Jacobians are computed in one vectorised call (memory: ``B x 512 x 14 x 14``
floats, 40 MB at 50 episodes)."""

_MEASURED = 6
"""Components of the error state a pose measurement observes: ``dtheta`` and ``dr``."""


@dataclass(frozen=True)
class BoundSummary:
    """Mean over episodes and its Monte-Carlo standard error (``std / sqrt(n)``) of one bound."""

    mean: float
    standard_error: float
    episodes: int

    def as_dict(self) -> dict[str, float | int]:
        return {"mean": self.mean, "standard_error": self.standard_error, "episodes": self.episodes}


def _summary(values: ArrayF) -> BoundSummary:
    values = np.asarray(values, dtype=float)
    n = values.size
    se = float(np.std(values, ddof=1) / math.sqrt(n)) if n > 1 else math.nan
    return BoundSummary(float(np.mean(values)), se, n)


@dataclass(frozen=True, eq=False)
class Bound:
    """The posterior Cramér-Rao bound of one scenario's episodes (module docstring).

    Attributes:
        scenario, split, seeds, cut: what it bounds (the scored window starts ``cut`` steps into
            the split).
        inertia: ``"known"`` or ``"estimated"`` (free tumbles; the log inertia ratios unknown with
            the scenario's prior), ``None`` for forced rotation.
        state_rmse: ``(B,)`` the 13-state bound per episode.
        group_rmse: ``{group: (B,)}`` per episode, in :data:`~fkn_bench.metrics.errors.GROUP_UNITS`.
        component_rmse: ``(B, 13)`` per state component.
        curves: ``{group: (T,)}`` the root of the mean over episodes of ``tr B_k[g]`` at every step
            of the split (the error curve an efficient estimator would follow; inf before a
            component is observable).
        times: ``(T,)`` the split's times, s.
    """

    scenario: str
    split: str
    seeds: tuple[int, ...]
    cut: int
    inertia: str | None
    state_rmse: Float[ArrayF, "B"]
    group_rmse: dict[str, Float[ArrayF, "B"]]
    component_rmse: Float[ArrayF, "B 13"]
    curves: dict[str, Float[ArrayF, "T"]] = field(repr=False)
    times: Float[ArrayF, "T"] = field(repr=False)

    def summary(self) -> dict[str, BoundSummary]:
        """``{"state": ..., group: ...}``: mean over episodes and Monte-Carlo standard error."""
        out = {"state": _summary(self.state_rmse)}
        out.update({g: _summary(self.group_rmse[g]) for g in GROUPS})
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-compatible: the settings, the per-episode values and their summary."""
        return {
            "scenario": self.scenario, "split": self.split, "seeds": list(self.seeds), "cut": self.cut,
            "inertia": self.inertia, "units": dict(GROUP_UNITS),
            "state_rmse": self.state_rmse.tolist(),
            "group_rmse": {g: v.tolist() for g, v in self.group_rmse.items()},
            "component_rmse": self.component_rmse.tolist(),
            "summary": {k: v.as_dict() for k, v in self.summary().items()},
        }


def efficiency(bound: float, rmse: float) -> float:
    """``bound / rmse`` (1.0: the best possible; NaN where either is not a positive finite
    number: a zero bound is a quantity the stated prior fixes, where no ratio says anything)."""
    if not (math.isfinite(bound) and math.isfinite(rmse)) or rmse <= 0 or bound <= 0:
        return math.nan
    return bound / rmse


def covariance_recursion(
    transitions: Any,
    prior: Float[ArrayF, "n n"],
    measured: Bool[ArrayB, "B T"],
    measurement_noise: Float[ArrayF, "T m m"],
    *,
    observed: int = _MEASURED,
    record: Any = None,
) -> Float[ArrayF, "B n n"]:
    """The bound's Riccati recursion in covariance form (module docstring) over ``T`` steps of a
    batch of ``B`` episodes.

    Args:
        transitions: ``transitions(start, stop) -> (F, Q)``: the transitions out of steps
            ``start .. stop - 1``, ``F (B, L, n, n)`` and ``Q (B, L, n, n)`` or None (no process
            noise), ``L = stop - start``.
        prior: ``(n, n)`` covariance of the state at step 0, before its measurement.
        measured: ``(B, T)`` where a measurement exists.
        measurement_noise: ``(T, m, m)`` measurement covariance at each step; ``H = [I_m 0]``
            with ``m = observed``.
        record: ``record(start, covariances (B, L, n, n))`` receives the posterior covariances of
            steps ``start .. start + L - 1`` (after each step's measurement, if any).

    Returns the predicted covariance after the last step, ``(B, n, n)``.
    """
    batch, steps = measured.shape
    n = prior.shape[0]
    P = np.broadcast_to(prior, (batch, n, n)).copy()
    eye = np.eye(n)
    for start in range(0, steps, CHUNK_STEPS):
        stop = min(steps, start + CHUNK_STEPS)
        F, Q = transitions(start, stop)
        posterior = np.empty((batch, stop - start, n, n)) if record is not None else None
        for j, k in enumerate(range(start, stop)):
            rows = measured[:, k]
            if rows.any():
                R = measurement_noise[k]
                S = P[:, :observed, :observed] + R
                gain = np.linalg.solve(S, P[:, :observed, :]).swapaxes(1, 2)  # K = P H^T S^-1 (S symmetric)
                A = eye - np.concatenate((gain, np.zeros((batch, n, n - observed))), axis=2)  # I - K H
                updated = A @ P @ A.swapaxes(1, 2) + gain @ R @ gain.swapaxes(1, 2)
                P = np.where(rows[:, None, None], 0.5 * (updated + updated.swapaxes(1, 2)), P)
            if posterior is not None:
                posterior[:, j] = P
            Fk = F[:, j]
            P = Fk @ P @ Fk.swapaxes(1, 2)
            if Q is not None:
                P = P + Q[:, j]
            P = 0.5 * (P + P.swapaxes(1, 2))
        if record is not None:
            record(start, posterior)
    return P


def _truth_model(scenario: Any) -> Any:
    """The model whose error-state transition is the truth's (module docstring)."""
    if scenario.dynamics == "forced":
        from fkn_bench.models.pose_twist import PoseTwistModel

        return PoseTwistModel()
    from fkn_bench.models.rigid_body import RigidBodyModel

    return RigidBodyModel(estimate_ratios=True, substeps=scenario.free_substeps)


def posterior_bound(
    scenario: Any,
    seeds: int | Sequence[int] | None = None,
    *,
    split: str = "test",
    cut: int = 100,
    inertia: Literal["scenario", "known"] = "scenario",
) -> Bound:
    """The PCRB of ``scenario`` (a name or :class:`~fkn_bench.scenarios.Scenario`) over the
    episodes ``seeds`` of ``split`` (an int ``N``: ``0 .. N-1``; default the scenario's
    ``test_episodes``), scored from ``cut`` steps into the split (module docstring).
    ``inertia="known"``: a free tumble's inertia known exactly (default: as the scenario states)."""
    from fkn_bench.envs import generate_episodes
    from fkn_bench.envs.episodes import kick_bursts, true_inertia
    from fkn_bench.models.error_state import error_transition
    from fkn_bench.models.rigid_body import inertia_ratios
    from fkn_bench.scenarios import get_scenario
    from fkn_bench.scenarios.prior import error_prior

    sc = get_scenario(scenario)
    if inertia not in ("scenario", "known"):
        raise ValueError(f"inertia must be 'scenario' or 'known' (got {inertia!r})")
    if seeds is None:
        seeds = sc.test_episodes
    seed_list = list(range(seeds)) if isinstance(seeds, (int, np.integer)) else [int(s) for s in seeds]
    start, stop = sc.split_bounds()[split]
    if not 0 <= cut < stop - start:
        raise ValueError(f"cut must be in [0, {stop - start}) for the {split} split of {sc.name} (got {cut})")
    free = sc.dynamics == "free"
    # where the recursion starts (module docstring): step 0, where the prior is stated, but for a free
    # tumble of a time-split scenario the split's first step
    first = start if free and sc.split_mode == "time" else 0
    episodes = generate_episodes(sc, seed_list, split="full" if sc.split_mode == "time" else split)
    truth, measured = episodes.truth[:, first:stop], episodes.valid[:, first:stop].copy()
    start, stop = start - first, stop - first  # (steps of the recursion from here on)
    measured[:, :start] = False  # the estimators start at the split: nothing before it is theirs
    prior = error_prior(sc, ratios=free)
    P0 = prior.covariance.copy()
    if first and P0[6, 6] > 0 and not prior.rate_mean.any():  # an isotropic rate: its magnitude where the split starts
        P0[6:9, 6:9] = np.mean(np.sum(truth[:, 0, 7:10] ** 2, axis=-1)) / 3.0 * np.eye(3)
    if free and inertia == "known":
        P0[12:, 12:] = 0.0
    model = _truth_model(sc)
    if free:
        ratios = np.array([inertia_ratios(j) for j in true_inertia(sc, episodes.seeds)])
        truth = np.concatenate((truth, np.broadcast_to(ratios[:, None, :], truth.shape[:2] + (2,))), axis=2)
    n = P0.shape[0]
    batch = truth.shape[0]
    kicks = None
    if sc.has_kicks:
        inside, _ = kick_bursts(sc, episodes.seeds)
        kicks = inside[:, first : first + stop]
        decay = math.exp(-sc.dt / sc.kick_decay)

    def transitions(a: int, b: int) -> tuple[ArrayF, ArrayF | None]:
        rows = truth[:, a:b].reshape(-1, truth.shape[2])
        _, F = error_transition(model, rows, sc.dt)
        F = np.asarray(F).reshape(batch, b - a, n, n)
        if kicks is None:
            return F, None
        F = F.copy()
        F[:, :, 6:9, 6:9] = decay * np.eye(3)
        after = np.zeros((batch, b - a), dtype=bool)  # burst noise u_{k+1} enters the transition out of k
        end = min(b + 1, stop)
        after[:, : end - a - 1] = kicks[:, a + 1 : end]
        Q = np.where(after[:, :, None, None], sc.kick_sigma**2 * np.eye(n)[None, None] * _rate_mask(n), 0.0)
        return F, Q

    factor = sc.noise_factor(np.arange(first, first + stop))
    variances = np.array([sc.sigma_attitude_effective**2] * 3 + [sc.sigma_position_effective**2] * 3)
    R = factor[:, None, None] ** 2 * np.diag(variances)[None]

    window = stop - start
    components = np.zeros((batch, window, 13))
    traces = np.zeros((batch, window, len(GROUPS)))
    q_truth = truth[:, start:stop, 0:4]

    def record(a: int, posterior: ArrayF) -> None:
        b = a + posterior.shape[1]
        lo, hi = max(a, start), b
        if hi <= lo:
            return
        P = posterior[:, lo - a : hi - a]
        diag = np.diagonal(P, axis1=2, axis2=3)
        theta = quat.theta_matrix(q_truth[:, lo - start : hi - start])  # (B, L, 4, 3): dq = Theta dtheta / 2
        attitude = P[:, :, 0:3, 0:3]
        components[:, lo - start : hi - start, 0:4] = 0.25 * np.einsum("blij,bljk,blik->bli", theta, attitude, theta)
        components[:, lo - start : hi - start, 4:13] = diag[:, :, 3:12]
        for g, block in enumerate((slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12))):
            traces[:, lo - start : hi - start, g] = diag[:, :, block].sum(-1)

    covariance_recursion(transitions, P0, measured, R, record=record)
    traces[..., 0] = np.degrees(np.sqrt(traces[..., 0])) ** 2  # attitude: rad^2 -> deg^2
    scored = slice(cut, window)
    group = {g: np.sqrt(traces[:, scored, i].mean(axis=1)) for i, g in enumerate(GROUPS)}
    curves = {g: np.sqrt(traces[:, :, i].mean(axis=0)) for i, g in enumerate(GROUPS)}
    return Bound(
        scenario=sc.name, split=split, seeds=tuple(seed_list), cut=int(cut),
        inertia=None if not free else ("known" if inertia == "known" or sc.inertia_error == 0 else "estimated"),
        state_rmse=np.sqrt(components[:, scored].mean(axis=(1, 2))),
        group_rmse=group,
        component_rmse=np.sqrt(components[:, scored].mean(axis=1)),
        curves=curves,
        times=np.arange(first + start, first + stop) * sc.dt,
    )


def _rate_mask(n: int) -> ArrayF:
    """``(n, n)``: ones on the rate's diagonal block (error components 6-8)."""
    mask = np.zeros((n, n))
    mask[6:9, 6:9] = 1.0
    return mask
