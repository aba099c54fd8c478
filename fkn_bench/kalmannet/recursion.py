"""KalmanNet's filter recursion: pure step functions on a small immutable state, and ``run``.

KalmanNet (Revach et al. 2022, section "KalmanNet") keeps the Kalman filter's flow and
replaces the gain: predict with the (known) model, ``x_t|t-1 = f(x_t-1|t-1)`` and
``y_t|t-1 = h(x_t|t-1)`` (the KF's prediction); compute the gain ``K_t`` with the network from the features
(the paper's input features)

* F1, observation difference ``dy~_t = y_t - y_t-1``,
* F2, innovation ``dy_t = y_t - y_t|t-1``,
* F3, forward-evolution difference ``dx~_t = x_t-1|t-1 - x_t-2|t-2``,
* F4, forward-update difference ``dx^_t = x_t-1|t-1 - x_t-1|t-2`` (the previous correction),

each L2-normalised; and update ``x_t|t = x_t|t-1 + K_t dy_t`` (the KF's update with the learned gain). Differences and the
correction are taken on a :class:`~fkn_bench.kalmannet.manifolds.Manifold` (the pose's tangent
space for the 13-state pose model: rotation vectors for the attitude, ``Exp`` for the
correction, the posterior quaternion renormalised by the model's ``normalize``).

The benchmark's conventions (those of :meth:`fkn_bench.filters.KalmanFilter.run`):

* Measurements are cleaned once by the model's ``sanitize``: non-finite or unusable ones are
  skipped, so no NaN reaches the arithmetic. A measurement is sign-aligned with the prediction
  (the model's ``align``) before it is differenced.
* Each sequence initialises at its first usable measurement (``model.initial_state``); before it,
  the model's prior state, propagated. A step without a usable measurement only predicts: the
  network is not run and its hidden states are kept. With measurements at some steps only
  (every 10th in the benchmark), "previous" in F1, F3 and F4 means the previous *update*: F1 is
  the difference to the last used measurement, F3 the difference between the posteriors of the
  last two updates, F4 the last update's correction (posterior minus its prior). With a
  measurement at every step this is the paper's definition. At the first update after the
  initialisation F3 and F4 are zero (the initial state is its own prior and predecessor).
* The network runs in its own dtype (float32 or float64); features are computed and the gain is
  applied in the measurements' dtype (float64 by default).

The error covariance KalmanNet's gain implies (KalmanNet learns no covariance; Klein et al.,
ICASSP 2022, recover one from the gain given the noise): on the pose tangent space the state
carries ``P`` of the 12-dim error ``[dtheta, dr, dw, dv]`` (world frame, as the multiplicative
EKF's), predicted by ``P = Phi P Phi^T + Q`` with the multiplicative EKF's error transition and
updated by the Joseph form with the learned gain, ``P = (I - K H) P (I - K H)^T + K R K^T``, which
is the error covariance of a filter with gain ``K`` whatever the gain, when the noise is ``(Q,
R)``. ``Q``, ``R`` and ``P0`` are the multiplicative EKF's manual tuning
(:data:`~fkn_bench.filters.mekf.MEKF_MANUAL_LAYOUT`), which the network never sees; the covariance
is therefore only as consistent as that tuning is for the gain learned, and the leaderboards'
NEES columns say how far it is. The gain enters it detached: the covariance does not shape the
training. KalmanNet is not gated: its features are L2-normalised, so its gain stays within the
range it was trained on, and its estimates stayed within a few times the manual EKF's error on
every committed scenario (:class:`NetworkSteps` gates Recursive KalmanNet).

The state is a :class:`KalmanNetState` (an immutable value); :meth:`KalmanNet.predict`,
:meth:`~KalmanNet.initial` and :meth:`~KalmanNet.update` are pure, and the same functions run the
batch (training, ``estimate``) and the online path (batch of one). What does not depend on the
gain network (the model and manifold, the features, truncated back-propagation, the batch loop
over any state of named tuples) is :class:`ManifoldRecursion`, which Recursive KalmanNet
(:mod:`fkn_bench.kalmannet.recursive`) shares.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple, TypeVar

import numpy as np
import torch
from torch import Tensor

from fkn_bench.filters.base import check_dt
from fkn_bench.filters.mekf import MEKF_MANUAL_LAYOUT
from fkn_bench.filters.recursion import Proposal, gate_threshold, scan, start_carry, tree_map
from fkn_bench.linalg import symmetrize
from fkn_bench.models.error_state import error_transition
from fkn_bench.models.base import StateSpaceModel
from fkn_bench.kalmannet.manifolds import Manifold, PoseTangent, manifold_for
from fkn_bench.kalmannet.network import GainNetwork, Hidden, normalize_features
from fkn_bench.training.data import Sequences
from fkn_bench.training.objectives import gaussian_nll
from fkn_bench.training.trainer import SequenceModel

__all__ = ["LEARNED_GATE_LEVEL", "CORRECTION_MARGIN", "joseph_update", "KalmanNet", "KalmanNetState", "KalmanNetRun", "ManifoldRecursion", "NetworkSteps"]

StateT = TypeVar("StateT")

LEARNED_GATE_LEVEL = 1.0 - 1e-6
"""The chi-square level of a learned filter's gate (:class:`NetworkSteps`): an innovation whose
NIS exceeds this quantile (35.9 for a 6-dimensional innovation) is not used, and
:data:`~fkn_bench.filters.recursion.GATE_REINITIALISE_AFTER` such measurements in a row restart the
track, the rule of the gated Kalman filters. Under a consistent covariance a rejection is a
one-in-a-million event, so the gate leaves the filter the measurements its gain was trained on;
it is looser than the Kalman filters' 0.999 because it tests a learned covariance. Without it
Recursive KalmanNet ran away where its training had not gone (a 13-state RMSE of 5e96 on
spin-noise5x)."""


CORRECTION_MARGIN = 100.0
"""How far beyond a Kalman gain's bound a learned filter's correction may go before its update is
refused (:meth:`ManifoldRecursion.plausible_correction` at this multiple of the gate's threshold).
A Kalman gain's correction has ``d^T P^-1 d`` at most the NIS; a learned gain with a separately
learned covariance does not keep to that: Recursive KalmanNet on its own training family (spin,
test seeds 0, 1, 14, 27, 45) made corrections up to 483 with every innovation within the gate
(threshold 38), while the updates by which it ran away after a hundred missing measurements
(spin-gap100) or at five times the noise (spin-noise5x) had 1e4 to 1e8."""


class KalmanNetState(NamedTuple):
    """A batch of KalmanNet states at one time (``B`` sequences).

    Attributes:
        mean: ``(B, n)`` current estimate (prior after a prediction, posterior after an update).
        last_posterior: ``(B, n)`` posterior of the last update (or the initial state).
        evolution: ``(B, n')`` F3 of the next update: the last update's posterior minus the
            posterior before it (zero after the initialisation).
        correction: ``(B, n')`` F4 of the next update: the last update's correction
            ``K dy``, which is its posterior minus its prior (``x [+] d [-] x = d``; zero after
            the initialisation). Stored, not recomputed: the difference of two equal states
            would be rounding noise, which the features' normalisation would blow up to unit
            length.
        last_measurement: ``(B, m)`` last measurement used (sanitised, sign-aligned).
        hidden: the three GRUs' hidden states (network dtype).
        covariance: ``(B, n', n')`` the error covariance the learned gain implies
            (:class:`KalmanNet`; None off the pose tangent space of a pose-twist model).
    """

    mean: Tensor
    last_posterior: Tensor
    evolution: Tensor
    correction: Tensor
    last_measurement: Tensor
    hidden: Hidden
    covariance: Tensor | None = None


class KalmanNetRun(NamedTuple):
    """Result of :meth:`KalmanNet.run` (batch first): ``means (B, T, n)``, ``updated (B, T)`` (a
    measurement update happened), ``initialised (B, T)``, the ``final`` state and the implied
    error ``covariances (B, T, n', n')`` (None off the pose tangent space)."""

    means: Tensor
    updated: Tensor
    initialised: Tensor
    final: KalmanNetState
    covariances: Tensor | None = None


def joseph_update(P: Tensor, K: Tensor, H: Tensor, R: Tensor) -> Tensor:
    """``(I - K H) P (I - K H)^T + K R K^T`` for ``P (B, n', n')``, ``K (B, n', m')``, ``H (m',
    n')``, ``R (m', m')``: the error covariance after an update with the gain ``K``, whichever
    gain it is, when the measurement noise is ``R`` (Joseph form; symmetrised)."""
    IKH = torch.eye(P.shape[-1], dtype=P.dtype, device=P.device) - K @ H
    return symmetrize(IKH @ P @ IKH.transpose(1, 2) + K @ R @ K.transpose(1, 2))


def _detached(state: StateT) -> StateT:
    return tree_map(lambda t: t.detach(), state)


class NetworkSteps:
    """A :class:`ManifoldRecursion`'s step functions for the one recursion
    (:mod:`fkn_bench.filters.recursion`), for the batch run and the online step alike: the
    network's update is the posterior; records nothing. With ``gate`` and a recursion whose
    :meth:`~ManifoldRecursion.innovation_covariance` is defined (:attr:`~ManifoldRecursion.gated`),
    the chi-square gate at :data:`LEARNED_GATE_LEVEL` on the innovation, a bound on the correction
    (:meth:`~ManifoldRecursion.plausible_correction` at :data:`CORRECTION_MARGIN` times the gate's
    threshold), and with them the lost-track rule of every gated filter; else no gate."""

    def __init__(self, recursion: ManifoldRecursion, *, gate: bool = True) -> None:
        self.recursion = recursion
        self.nis_threshold = gate_threshold(LEARNED_GATE_LEVEL, recursion.manifold.measurement_tangent_dim)[1] if (
            gate and recursion.gated) else math.inf

    def predict(self, state: Any, t: int, dt: float) -> Any:
        return self.recursion.predict(state, dt)

    def initial(self, state: Any, z: Tensor, t: int) -> Any:
        return self.recursion.initial(state, z)

    def propose(self, state: Any, z: Tensor, rows: Tensor, t: int) -> Proposal:
        if self.nis_threshold == math.inf:
            return Proposal(self.recursion.update(state, z))
        innovation = self.recursion.manifold.measurement_difference(self.recursion.model.align(z, state.mean),
                                                                    self.recursion.model.measure(state.mean))
        return Proposal(self.recursion.update(state, z), innovation, self.recursion.innovation_covariance(state))

    def commit(self, state: Any, z: Tensor, rows: Tensor, proposal: Proposal, t: int) -> tuple[Any, Tensor]:
        """The network's posterior; gated, only for the rows whose correction is within
        :data:`CORRECTION_MARGIN` of a Kalman update's bound (:meth:`ManifoldRecursion.plausible_correction`)."""
        if self.nis_threshold == math.inf:
            return proposal.state, rows
        plausible = self.recursion.plausible_correction(state, proposal.state, CORRECTION_MARGIN * self.nis_threshold)
        return proposal.state, rows & (plausible if isinstance(rows, Tensor) else plausible.numpy())

    def record(self, *args: Any) -> None:
        pass


class _Recorder(NetworkSteps):
    """:class:`NetworkSteps` of :meth:`ManifoldRecursion.recurse`, keeping ``record(state)`` of every step."""

    def __init__(self, recursion: ManifoldRecursion, record: Callable[[Any], tuple[Tensor, ...]], *, gate: bool) -> None:
        super().__init__(recursion, gate=gate)
        self.record_state = record
        self.records: list[tuple[Tensor, ...]] = []
        self.updated: list[Tensor] = []
        self.initialised: list[Tensor] = []

    def record(self, t: int, prior: Any, state: Any, innovation: Any, used: Tensor | None, initialised: Tensor) -> None:
        self.records.append(self.record_state(state))
        self.updated.append(torch.zeros_like(initialised) if used is None else used)
        self.initialised.append(initialised)


class ManifoldRecursion(SequenceModel):
    """What KalmanNet and Recursive KalmanNet share (see module docstring): the process model,
    the :class:`Manifold` of differences and corrections, truncated back-propagation, the
    features F1-F4 and the batch loop. A subclass brings its state (a named tuple with at least
    KalmanNet's ``mean``, ``last_measurement``, ``evolution`` and ``correction``, possibly nested
    named tuples of tensors) and the pure steps :meth:`prior`, :meth:`predict`, :meth:`initial`
    and :meth:`update`; :meth:`recurse` runs them over a batch of sequences.

    Args:
        model: the process and measurement model (any :class:`~fkn_bench.models.base.StateSpaceModel`).
        manifold: ``"auto"``, ``"pose-tangent"`` or ``"euclidean"``; or a :class:`Manifold`.
        detach_every: truncated back-propagation through time (None: full; see :class:`KalmanNet`).
    """

    def __init__(self, model: StateSpaceModel, *, manifold: str | Manifold = "auto", detach_every: int | None = None) -> None:
        super().__init__()
        self.model = model
        self.manifold = manifold if isinstance(manifold, Manifold) else manifold_for(model, manifold)
        if detach_every is not None and detach_every < 1:
            raise ValueError(f"detach_every must be >= 1 or None (got {detach_every})")
        self.detach_every = detach_every
        # H (m', n') and the manual measurement noise R (m', m') as buffers, so they follow the module's device
        self.register_buffer("H", torch.from_numpy(np.asarray(self.manifold.measurement_matrix(), dtype=np.float64)),
                             persistent=False)
        self.register_buffer("manual_measurement_noise", torch.tensor(MEKF_MANUAL_LAYOUT.r_default, dtype=torch.float64)
                             .square().diag() if isinstance(self.manifold, PoseTangent) else None, persistent=False)

    # ------------------------------------------------------------------ steps (pure), by subclasses
    def prior(self, batch: int, dtype: torch.dtype = torch.float64, device: torch.device | None = None) -> Any:
        raise NotImplementedError

    def predict(self, state: Any, dt: float) -> Any:
        raise NotImplementedError

    def initial(self, state: Any, z: Tensor) -> Any:
        raise NotImplementedError

    def update(self, state: Any, z: Tensor) -> Any:
        raise NotImplementedError

    gated = False
    """Whether the state carries an error covariance (:meth:`error_covariance`) and the
    measurement noise is stated (:meth:`measurement_noise`), so that the estimates are gated
    (:class:`NetworkSteps`)."""

    def error_covariance(self, state: Any) -> Tensor:
        """``P (B, n', n')``, the covariance of the tangent-space error of ``state`` (its ``covariance``)."""
        return state.covariance

    def measurement_noise(self, dtype: torch.dtype) -> Tensor:
        """``R (m', m')``: on the pose tangent space the multiplicative EKF's manual measurement
        noise (:data:`~fkn_bench.filters.mekf.MEKF_MANUAL_LAYOUT`: 0.2 rad, 0.1 m), which the
        networks do not learn (the gate's ``S = H P H^T + R``; KalmanNet's implied covariance)."""
        if self.manual_measurement_noise is None:
            raise NotImplementedError(f"no measurement noise is stated on the {self.manifold.name} manifold")
        return self.manual_measurement_noise.to(dtype)

    def innovation_covariance(self, state: Any) -> Tensor:
        """``S = H P H^T + R (B, m', m')`` at a predicted ``state``: the covariance the gate tests
        the innovation against (``H`` the manifold's measurement matrix)."""
        P = self.error_covariance(state)
        H = self.H.to(P.dtype)
        return H @ P @ H.T + self.measurement_noise(P.dtype)

    def plausible_correction(self, prior: Any, posterior: Any, threshold: float) -> Tensor:
        """``(B,)`` True where the update's correction ``d`` (the posterior's ``correction``) has
        ``d^T P^-1 d <= threshold`` under the prior's error covariance ``P``. A Kalman update
        ``d = P H^T S^-1 nu`` has ``d^T P^-1 d = nu^T S^-1 H P H^T S^-1 nu <= nu^T S^-1 nu`` (the
        NIS, as ``H P H^T <= S``); the gate applies it with a margin
        (:data:`CORRECTION_MARGIN`), so that a refused correction is far outside the range of any
        Kalman gain."""
        d = posterior.correction.detach()
        P = self.error_covariance(prior).detach()
        try:
            length = (d * torch.linalg.solve(P, d[..., None])[..., 0]).sum(-1)
        except RuntimeError:  # a singular P: no update is plausible
            return torch.zeros(d.shape[0], dtype=torch.bool, device=d.device)
        return length <= threshold  # (NaN fails)

    def features(self, state: Any, z: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """``(F1, F2, F3, F4)`` at a predicted ``state`` for usable measurements ``z`` (``z``
        sign-aligned with the prediction first), not yet normalised; F2 is the innovation."""
        prior = state.mean
        f1 = self.manifold.measurement_difference(z, state.last_measurement)
        innovation = self.manifold.measurement_difference(z, self.model.measure(prior))
        return f1, innovation, state.evolution, state.correction

    # ------------------------------------------------------------------ sequences
    def recurse(
        self, measurements: Tensor, mask: Tensor, *, dt: float, record: Callable[[Any], tuple[Tensor, ...]]
    ) -> tuple[tuple[Tensor, ...], Tensor, Tensor, Any]:
        """Filter a batch: ``measurements (B, T, m)`` (entries outside ``mask`` are ignored and
        may be NaN), ``mask (B, T)`` -> ``(records, updated (B, T), initialised (B, T), final
        state)``, ``records`` the tensors ``record(state)`` of every step stacked on axis 1. The
        rules are the project's one recursion (:func:`fkn_bench.filters.recursion.scan`), gated
        where the recursion is :attr:`gated` and no gradients are recorded (estimation and the
        trainer's validation; the training loss sees every measurement, as the gain is trained
        on them). float64 unless the measurements
        are of another floating dtype."""
        if measurements.dim() != 3 or measurements.shape[-1] != self.manifold.measurement_dim:
            raise ValueError(f"measurements must have shape (B, T, {self.manifold.measurement_dim}) (got {tuple(measurements.shape)})")
        if mask.shape != measurements.shape[:2]:
            raise ValueError(f"mask must have shape {tuple(measurements.shape[:2])} (got {tuple(mask.shape)})")
        batch, steps, _ = measurements.shape
        if batch == 0 or steps == 0:
            raise ValueError(f"measurements hold no sequences or no time steps (shape {tuple(measurements.shape)})")
        dt = check_dt(dt)
        z_all, usable = self.model.sanitize(measurements, mask.bool())
        truncate = self.detach_every if torch.is_grad_enabled() else None
        begin = None if truncate is None else (lambda state, t: _detached(state) if t > 0 and t % truncate == 0 else state)
        state = self.prior(batch, measurements.dtype, measurements.device)
        recorder = _Recorder(self, record, gate=not torch.is_grad_enabled())
        final = scan(recorder, start_carry(recorder, state, torch.zeros(batch, dtype=torch.bool, device=measurements.device)), z_all, usable,
                     dt, begin=begin)
        stacked = tuple(torch.stack(parts, 1) for parts in zip(*recorder.records))
        return stacked, torch.stack(recorder.updated, 1), torch.stack(recorder.initialised, 1), final.state

    def sequence_loss(self, sequences: Sequences, *, dt: float, loss_cut: int, objective: str) -> tuple[Tensor, Tensor]:
        """``(objective, 13-state MSE)`` over steps ``loss_cut:``: ``supervised``, the MSE; or, where
        :attr:`objectives` has it (a recursion whose ``run`` reports ``covariances``),
        ``gaussian-nll``, the mean Gaussian NLL of the true state's error (tangent coordinates)
        under the reported covariance, per step."""
        if objective not in self.objectives:
            name = getattr(self, "architecture", type(self).__name__).split(" (")[0]
            raise ValueError(f"{name} trains with the objectives {list(self.objectives)} (got {objective!r})")
        if objective != "gaussian-nll":
            return super().sequence_loss(sequences, dt=dt, loss_cut=loss_cut, objective=objective)
        run = self.run(sequences.measurements, sequences.mask, dt=dt)  # type: ignore[attr-defined]
        if loss_cut >= run.means.shape[1]:
            raise ValueError(f"loss_cut {loss_cut} leaves no steps of {run.means.shape[1]}")
        means, truth = run.means[:, loss_cut:], sequences.truth[:, loss_cut:]
        if truth.shape[-1] != means.shape[-1]:
            raise ValueError(f"the Gaussian NLL needs the whole state in the truth ({means.shape[-1]} components, "
                             f"truth has {truth.shape[-1]})")
        mse = self.manifold.state_error(means, truth).square().mean()
        flat_means, flat_truth = means.reshape(-1, means.shape[-1]), truth.reshape(-1, truth.shape[-1]).to(means.dtype)
        errors = self.manifold.state_difference(flat_truth, flat_means)
        n = self.manifold.state_tangent_dim
        return gaussian_nll(errors, run.covariances[:, loss_cut:].reshape(-1, n, n)), mse

    def run_means(self, measurements: Tensor, mask: Tensor, *, dt: float) -> Tensor:
        return self.recurse(measurements, mask, dt=dt, record=lambda s: (s.mean,))[0][0]

    def sequence_mse(self, sequences: Sequences, *, dt: float, loss_cut: int) -> Tensor:
        """Mean squared state error (the manifold's, sign-safe for the quaternion) over steps
        ``loss_cut:``: the supervised objective of :class:`~fkn_bench.training.Trainer`."""
        means = self.run_means(sequences.measurements, sequences.mask, dt=dt)
        if loss_cut >= means.shape[1]:
            raise ValueError(f"loss_cut {loss_cut} leaves no steps of {means.shape[1]}")
        return self.manifold.state_error(means[:, loss_cut:], sequences.truth[:, loss_cut:]).square().mean()


class KalmanNet(ManifoldRecursion):
    """KalmanNet (architecture 2) on a state-space model (see module docstring).

    Args:
        model: the process and measurement model; only its ``predict``, ``measure``, ``align``,
            ``normalize``, ``sanitize``, ``initial_state``, ``prior_state``, ``state_dim`` and
            ``measurement_dim`` are used (any :class:`~fkn_bench.models.base.StateSpaceModel`).
        manifold: ``"auto"`` (pose tangent space for the 13-state pose model, else Euclidean),
            ``"pose-tangent"`` or ``"euclidean"``; or a :class:`Manifold`.
        in_mult, out_mult: the paper's input and output multipliers of the gain network.
        network_dtype: the network's dtype.
        detach_every: truncated back-propagation through time: while gradients are recorded,
            the recurrent state (estimate, memories, hidden states) is detached every this many
            time steps (None: full back-propagation through the sequence).
        initial_gain, output_scale: the gain network starts near ``initial_gain * G`` (``G`` the
            manifold's :meth:`~Manifold.observed_gain`) with FC2's output weights scaled by
            ``output_scale`` (None and 1: the paper's default initialisation; see
            :class:`~fkn_bench.kalmannet.network.GainNetwork`).
    """

    def __init__(
        self,
        model: StateSpaceModel,
        *,
        manifold: str | Manifold = "auto",
        in_mult: int = 5,
        out_mult: int = 40,
        network_dtype: torch.dtype = torch.float32,
        detach_every: int | None = None,
        initial_gain: float | None = None,
        output_scale: float = 1.0,
    ) -> None:
        super().__init__(model, manifold=manifold, detach_every=detach_every)
        start = None if initial_gain is None else initial_gain * torch.from_numpy(self.manifold.observed_gain())
        self.network = GainNetwork(self.manifold.state_tangent_dim, self.manifold.measurement_tangent_dim,
                                   in_mult=in_mult, out_mult=out_mult, dtype=network_dtype, initial_gain=start,
                                   output_scale=output_scale)
        self.implies_covariance = isinstance(self.manifold, PoseTangent) and "pose-state" in getattr(model, "offers", ())
        if self.implies_covariance:
            noise = MEKF_MANUAL_LAYOUT.default_noise()
            self.register_buffer("process_covariance", noise.process, persistent=False)
            self.register_buffer("initial_covariance", noise.initial, persistent=False)

    # ------------------------------------------------------------------ steps (pure)
    def _initial_covariance(self, like: Tensor) -> Tensor | None:
        return self.initial_covariance.to(like).expand(like.shape[0], -1, -1) if self.implies_covariance else None

    def prior(self, batch: int, dtype: torch.dtype = torch.float64, device: torch.device | None = None) -> KalmanNetState:
        """The state reported before a sequence's first usable measurement."""
        mean = self.model.prior_state(batch, dtype).to(device)  # (a model's prior is on the CPU)
        tangent = mean.new_zeros(batch, self.manifold.state_tangent_dim)
        return KalmanNetState(mean, mean, tangent, tangent, mean.new_zeros(batch, self.manifold.measurement_dim),
                              self.network.initial_hidden(batch), self._initial_covariance(mean))

    def predict(self, state: KalmanNetState, dt: float) -> KalmanNetState:
        """The state predicted over ``dt`` seconds by the model (the KF's prediction; the implied
        covariance ``Phi P Phi^T + Q`` with the multiplicative EKF's error transition); memories unchanged."""
        mean = self.model.predict(state.mean, dt)
        if state.covariance is None:
            return state._replace(mean=mean)
        Phi = error_transition(self.model, state.mean.detach(), dt)[1]
        P = Phi @ state.covariance @ Phi.transpose(1, 2) + self.process_covariance.to(Phi)
        return state._replace(mean=mean, covariance=symmetrize(P))

    def initial(self, state: KalmanNetState, z: Tensor) -> KalmanNetState:
        """The state initialised from usable measurements ``z (B, m)`` (hidden states at their
        priors, the implied covariance at ``P0``)."""
        mean = self.model.initial_state(z)
        tangent = mean.new_zeros(z.shape[0], self.manifold.state_tangent_dim)
        return KalmanNetState(mean, mean, tangent, tangent, z, self.network.initial_hidden(z.shape[0]),
                              self._initial_covariance(mean))

    def update(self, state: KalmanNetState, z: Tensor) -> KalmanNetState:
        """The measurement update of every row with usable measurements ``z (B, m)``:
        ``x+ = x- [+] K dy``, then the model's ``normalize`` (unit quaternion)."""
        prior = state.mean
        z = self.model.align(z, prior)
        f1, innovation, f3, f4 = self.features(state, z)
        gain, hidden = self.network(*(normalize_features(f) for f in (f1, innovation, f3, f4)), state.hidden)
        delta = (gain.to(prior.dtype) @ innovation[:, :, None])[:, :, 0]
        posterior = self.model.normalize(self.manifold.correct(prior, delta))[0]
        evolution = self.manifold.state_difference(posterior, state.last_posterior)
        covariance = None if state.covariance is None else joseph_update(
            state.covariance, gain.detach().to(prior.dtype), self.H.to(prior.dtype),
            self.measurement_noise(prior.dtype))
        return KalmanNetState(posterior, posterior, evolution, delta, z, hidden, covariance)

    # ------------------------------------------------------------------ sequences
    def run(self, measurements: Tensor, mask: Tensor, *, dt: float) -> KalmanNetRun:
        """Filter a batch: ``measurements (B, T, m)`` (entries outside ``mask`` are ignored and
        may be NaN), ``mask (B, T)`` -> :class:`KalmanNetRun`. float64 unless the measurements
        are of another floating dtype."""
        if not self.implies_covariance:
            (means,), updates, initialised, final = self.recurse(measurements, mask, dt=dt, record=lambda s: (s.mean,))
            return KalmanNetRun(means, updates, initialised, final)
        (means, covariances), updates, initialised, final = self.recurse(
            measurements, mask, dt=dt, record=lambda s: (s.mean, s.covariance))
        return KalmanNetRun(means, updates, initialised, final, covariances)

    def describe(self) -> dict[str, Any]:
        net = self.network
        return {
            "architecture": "KalmanNet architecture 2 (Revach et al. 2022)",
            "process_model": type(self.model).__name__,
            "manifold": self.manifold.name,
            "state_tangent_dim": net.n,
            "measurement_tangent_dim": net.m,
            "in_mult": net.in_mult,
            "out_mult": net.out_mult,
            "network_dtype": str(net.dtype).removeprefix("torch."),
            "weights": int(sum(p.numel() for p in net.parameters())),
        }
