"""Split-KalmanNet: the Kalman gain from two learned covariances, one for the state, one for the innovation.

G. Choi, J. Park, N. Shlezinger, Y. C. Eldar and N. Lee, "Split-KalmanNet: A Robust Model-Based
Deep Learning Approach for State Estimation", IEEE Trans. Vehicular Technology 72(9), 2023
(arXiv:2210.09636). The filter keeps the (extended) Kalman filter's flow, as KalmanNet does, and
splits the gain ``K = P H^T S^-1`` into its two covariances, each tracked by its own recurrent
network at every measurement update:

* the state branch, fed the state differences (KalmanNet's F3, the last forward evolution
  ``x_t-1|t-1 [-] x_t-2|t-2``, and F4, the last correction ``x_t-1|t-1 [-] x_t-1|t-2``), outputs
  the prior error covariance ``P^_t|t-1`` (``n' x n'``);
* the measurement branch, fed the measurement differences (F1, ``y_t [-] y_t-1``, and F2, the
  innovation ``dy_t = y_t [-] h(x_t|t-1)``), outputs the inverse innovation covariance
  ``W^_t = S^_t^-1`` (``m' x m'``);

and the update is ``K_t = P^_t|t-1 H^T W^_t``, ``x_t|t = x_t|t-1 [+] K_t dy_t``. Each branch is
``FC-in (ReLU) -> GRU -> FC-out (ReLU) -> linear``
(:class:`~fkn_bench.kalmannet.recursive.GRUBranch`), its hidden state zero at a sequence's start;
training minimises the MSE of the state (the paper's loss, ``objective = "supervised"``).

Learned and derived, with shapes (``n'`` and ``m'`` the tangent dimensions: 12 and 6 on the pose
model, ``n`` and ``m`` on a Euclidean one):

* learned: the branches' outputs ``A (n' x n')`` and ``B (m' x m')``, read relative to fixed
  reference covariances ``P_ref = diag(p0^2)`` and ``S_ref = H P_ref H^T / g`` (``g`` the
  ``initial_gain``; ``C_P``, ``C_S`` their Cholesky factors): ``P^ = C_P (I + A) C_P^T`` and
  ``W^ = C_S^-T (I + B) C_S^-1``, so that zero outputs give ``K = g G`` (``G`` the manifold's
  observed gain, the start of KalmanNet and Recursive KalmanNet). As in the paper these matrices
  are unconstrained (neither symmetric nor definite) and enter the gain as they are.
* derived, the error covariance reported (the NEES columns' ``P``, the gate's): the paper's code
  reports ``(I - K H) P^``, neither symmetric nor definite for an unconstrained ``P^``, and the MSE
  the paper trains on identifies ``P^`` and ``W^`` only up to a common scale (``(c P^, W^ / c)``
  give one gain): on the paper's example (:mod:`fkn_bench.kalmannet.rotation`) a covariance updated
  from ``P^`` (its nearest SPD matrix, Joseph form; stated ``p0 = 1``) had a mean NEES of 4e3 to 3e4
  in three trainings, where 2 is consistent. So the covariance reported is the one the learned gain
  implies under the stated noise, as KalmanNet's here (Klein, Revach, Shlezinger et al.,
  "Uncertainty in data-driven Kalman filtering for partially known state-space models", ICASSP
  2022): ``P_t|t-1 = F P_t-1|t-1 F^T + Q``, ``P_t|t = (I - K H) P_t|t-1 (I - K H)^T + K R K^T +
  floor^2 I`` (Joseph form: the error covariance of an update with the gain ``K``, whatever the
  gain, when the prior error has covariance ``P_t|t-1`` and the measurement noise is ``R``), from
  ``P_0 = P_ref``; symmetric positive definite by construction. ``Q = diag(q^2)`` and ``R =
  diag(r^2)`` are the stated noise (below), which the networks never see (``Q`` is a parameter,
  ``diag(softplus(.)^2)``, which only Cholesky-KalmanNet's covariance objective trains; here it
  stays at ``q``): the covariance is exact where they are a linear model's true noise (the example's
  mean NEES: 1.1) and otherwise as consistent as they are, which the leaderboards' NEES columns say.
  It is computed from detached tensors and does not shape the training. Cholesky-KalmanNet
  (:mod:`fkn_bench.kalmannet.cholesky`) learns SPD covariances and trains on them.

Frames and units as :mod:`fkn_bench.kalmannet.recursion`: on the pose model the error is
``[dtheta, dr, dw, dv]`` (rad, m, rad/s, m/s; world frame, ``q_true = Exp(dtheta) (x) q_est``),
the measurement's ``[dtheta, dr]``, ``H = [I6 0]``; ``F`` is the multiplicative EKF's error
transition over ``dt`` (constant rate or rigid body), and the stated noise and references
(``q``, ``r``, ``p0``: :func:`reference_stds`) are the multiplicative EKF's manual tuning
(:data:`~fkn_bench.filters.mekf.MEKF_MANUAL_LAYOUT`: ``p0`` 0.2 rad, 0.1 m, 0.2 rad/s, 3 mm/s;
``r`` 0.2 rad, 0.1 m). On a Euclidean model ``F`` is the model's Jacobian and ``H`` its matrix,
and the stated noise is the model's noise layout (``model.layout``; ones where it has none of the
right size).

Deviations from the paper (and its public code, geonchoi/Split-KalmanNet), each for a reason:

* Inputs: the paper's branches also see the linearisation error ``h(x) - H x`` and the Jacobian
  ``H``, which are zero and constant on these manifolds (the measurement's tangent is linear in
  the state's), so they are left out. The features are divided by the reference standard
  deviations (``p0`` for F3 and F4, ``sqrt(diag S_ref)`` for F1 and F2; the paper feeds them raw)
  and clipped to ``+-`` :data:`INPUT_CLIP`, so that the attitude in radians and a velocity in mm/s
  enter on one scale and a gross outlier cannot overflow the network.
* Sizes: the reference code's branches are ``FC (80 (n + m)) -> 2-layer GRU (2 (n^2 + m^2)) ->
  FC (4 n m)``; here one GRU layer and the widths of :class:`GRUBranch` (``in_mult``,
  ``hidden_mult``, ``out_mult``: 0.6 million weights on the pose model with the defaults 5, 2, 2).
* Initialisation: outputs relative to the reference covariances, output weights scaled by
  ``output_scale`` and zero bias (above); the paper's code starts the GRUs at random hidden states
  and its output layers at PyTorch's default.
* Training: the paper alternates the two branches (one Adam step on each in turn, separate
  optimisers); here the shared :class:`~fkn_bench.training.Trainer` takes joint Adam steps.
* Sparse measurements, the gate, the quaternion: as Recursive KalmanNet
  (:mod:`fkn_bench.kalmannet.recursive`): the steps without a measurement predict mean and
  covariance with the multiplicative EKF's prediction (the EKF's on a Euclidean model); where no
  gradients are recorded, on the pose tangent space, an innovation whose NIS under ``S = H P H^T +
  R`` exceeds the 1 - 1e-6 chi-square quantile, or a correction a hundred times beyond any
  Kalman gain's under ``P`` (the predicted reported covariance), is not used, and three in a row
  restart the track (:class:`~fkn_bench.kalmannet.recursion.NetworkSteps`).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import torch
from torch import Tensor, nn
from torch.nn import functional

from fkn_bench.filters import ExtendedKalmanFilter
from fkn_bench.filters.base import FilterState
from fkn_bench.filters.mekf import MEKF_MANUAL_LAYOUT, MultiplicativeEKF
from fkn_bench.kalmannet.manifolds import Manifold, PoseTangent
from fkn_bench.kalmannet.recursion import ManifoldRecursion, joseph_update
from fkn_bench.kalmannet.recursive import GRUBranch, _inverse_softplus
from fkn_bench.linalg import symmetrize
from fkn_bench.models.base import StateSpaceModel

__all__ = ["INPUT_CLIP", "SplitHidden", "SplitKalmanNet", "SplitKalmanNetRun", "SplitKalmanNetState", "reference_stds"]

INPUT_CLIP = 1e3
"""Largest magnitude of a whitened feature entering the branches (reference standard deviations)."""


def reference_stds(model: StateSpaceModel, manifold: Manifold) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(q (n',), r (m',), p0 (n',))``: the reference standard deviations of the process noise,
    the measurement noise and the initial error (the multiplicative EKF's manual tuning on the pose
    tangent space; else the model's noise layout where its sizes match, ones where not)."""
    n, m = manifold.state_tangent_dim, manifold.measurement_tangent_dim
    layout = MEKF_MANUAL_LAYOUT if isinstance(manifold, PoseTangent) else getattr(model, "layout", None)

    def pick(values: Any, size: int) -> np.ndarray:
        out = np.asarray(values if values is not None else (), dtype=np.float64)
        return out if out.shape == (size,) and bool((out > 0).all()) else np.ones(size)

    return (pick(getattr(layout, "q_default", None), n), pick(getattr(layout, "r_default", None), m),
            pick(getattr(layout, "p0_default", None), n))


class SplitHidden(NamedTuple):
    """The branches' GRU hidden states, ``state`` and ``measurement`` (network dtype)."""

    state: Tensor
    measurement: Tensor


class SplitKalmanNetState(NamedTuple):
    """A batch of Split-KalmanNet (or Cholesky-KalmanNet) states at one time: KalmanNet's fields
    (``mean``, ``last_posterior``, ``evolution``, ``correction``, ``last_measurement``; see
    :class:`~fkn_bench.kalmannet.KalmanNetState`), ``covariance (B, n', n')``, the reported error
    covariance in tangent coordinates (module docstring), and the branches' ``hidden`` states."""

    mean: Tensor
    last_posterior: Tensor
    evolution: Tensor
    correction: Tensor
    last_measurement: Tensor
    covariance: Tensor
    hidden: SplitHidden


class SplitKalmanNetRun(NamedTuple):
    """Result of :meth:`SplitKalmanNet.run` (batch first): ``means (B, T, n)``, ``covariances
    (B, T, n', n')``, ``updated (B, T)``, ``initialised (B, T)``, ``final``."""

    means: Tensor
    covariances: Tensor
    updated: Tensor
    initialised: Tensor
    final: SplitKalmanNetState


class SplitKalmanNet(ManifoldRecursion):
    """Split-KalmanNet on a state-space model (see module docstring).

    Args:
        model: the process and measurement model; on the pose tangent space a pose-twist model
            (constant rate or rigid body), whose error transition the multiplicative EKF forms.
        manifold: ``"auto"``, ``"pose-tangent"`` or ``"euclidean"``; or a :class:`Manifold`.
        in_mult, hidden_mult, out_mult: the branches' widths (:class:`GRUBranch`).
        network_dtype: the branches' dtype (the filter runs in the measurements' dtype).
        detach_every: truncated back-propagation through time (as KalmanNet's).
        initial_gain: ``g > 0``: zero branch outputs give the gain ``g G`` (the references).
        output_scale: factor on both branches' output weights at initialisation.
        std_floor: ``std_floor^2 I`` is added to every reported posterior covariance.
    """

    objectives: tuple[str, ...] = ("supervised",)
    architecture = "Split-KalmanNet (Choi et al., IEEE TVT 2023)"
    covariance_is_trained = False
    """Whether the reported covariance keeps its gradients (Cholesky-KalmanNet's trains on it)."""

    def __init__(
        self,
        model: StateSpaceModel,
        *,
        manifold: str | Manifold = "auto",
        in_mult: int = 5,
        hidden_mult: int = 2,
        out_mult: int = 2,
        network_dtype: torch.dtype = torch.float32,
        detach_every: int | None = None,
        initial_gain: float = 0.5,
        output_scale: float = 0.1,
        std_floor: float = 1e-4,
    ) -> None:
        super().__init__(model, manifold=manifold, detach_every=detach_every)
        if not (initial_gain > 0 and std_floor > 0):
            raise ValueError(f"initial_gain and std_floor must be > 0 (got {initial_gain}, {std_floor})")
        n, m = self.manifold.state_tangent_dim, self.manifold.measurement_tangent_dim
        self.n, self.m, self.std_floor = n, m, float(std_floor)
        self.in_mult, self.hidden_mult, self.out_mult = int(in_mult), int(hidden_mult), int(out_mult)
        q, r, p0 = (torch.from_numpy(v) for v in reference_stds(model, self.manifold))
        H = torch.from_numpy(np.asarray(self.manifold.measurement_matrix(), dtype=np.float64))
        P_ref = torch.diag(p0.square())
        S_ref = symmetrize(H @ P_ref @ H.T) / initial_gain
        self.register_buffer("H", H, persistent=False)
        self.register_buffer("R", torch.diag(r.square()), persistent=False)
        self.register_buffer("initial_covariance", P_ref, persistent=False)
        self.register_buffer("state_root", torch.diag(p0), persistent=False)  # C_P
        self.register_buffer("measurement_root", torch.linalg.cholesky(S_ref), persistent=False)  # C_S
        self.register_buffer("state_scale", p0, persistent=False)
        self.register_buffer("measurement_scale", S_ref.diagonal().sqrt(), persistent=False)
        self.state_branch = GRUBranch(2 * n, self.branch_outputs(n), in_mult=in_mult, hidden_mult=hidden_mult,
                                      out_mult=out_mult, dtype=network_dtype, output_bias=self.output_bias(n),
                                      output_scale=output_scale)
        self.measurement_branch = GRUBranch(2 * m, self.branch_outputs(m), in_mult=in_mult, hidden_mult=hidden_mult,
                                            out_mult=out_mult, dtype=network_dtype, output_bias=self.output_bias(m),
                                            output_scale=output_scale)
        self.process_raw = nn.Parameter(torch.tensor([_inverse_softplus(float(s)) for s in q], dtype=torch.float64))
        self._propagator: Any = (MultiplicativeEKF(model=model) if isinstance(self.manifold, PoseTangent)
                                 else ExtendedKalmanFilter(model=model))

    # ------------------------------------------------------------------ the branches' outputs
    def branch_outputs(self, k: int) -> int:
        """Outputs of a branch for a ``k x k`` matrix: all ``k^2`` entries (row-major)."""
        return k * k

    def output_bias(self, k: int) -> Tensor:
        """The output layer's bias: zero, so that a zero output gives the reference."""
        return torch.zeros(self.branch_outputs(k), dtype=torch.float64)

    def prior_and_gain(self, state_raw: Tensor, measurement_raw: Tensor) -> tuple[Tensor | None, Tensor]:
        """``(P (B, n', n') or None, K (B, n', m'))`` from the branches' outputs: the prior error
        covariance the reported covariance is updated from (None: the predicted reported
        covariance) and the gain ``K = P^ H^T W^`` (module docstring)."""
        eye_n = torch.eye(self.n, dtype=state_raw.dtype, device=state_raw.device)
        eye_m = torch.eye(self.m, dtype=state_raw.dtype, device=state_raw.device)
        C_P, C_S = self.state_root.to(state_raw), self.measurement_root.to(state_raw)
        P_hat = C_P @ (eye_n + state_raw.reshape(-1, self.n, self.n)) @ C_P.T
        inverse_root = torch.linalg.solve_triangular(C_S, eye_m, upper=False)  # C_S^-1
        W_hat = inverse_root.T @ (eye_m + measurement_raw.reshape(-1, self.m, self.m)) @ inverse_root
        return None, P_hat @ self.H.to(state_raw).T @ W_hat

    # ------------------------------------------------------------------ pieces
    @property
    def gated(self) -> bool:  # type: ignore[override]
        """On the pose tangent space, where ``R`` is the manual tuning's."""
        return isinstance(self.manifold, PoseTangent)

    def measurement_noise(self, dtype: torch.dtype) -> Tensor:
        """``R (m', m')``, the stated measurement noise: the multiplicative EKF's manual tuning on
        the pose tangent space (as :meth:`ManifoldRecursion.measurement_noise`), the model's
        layout on a Euclidean model (:func:`reference_stds`)."""
        return self.R.to(dtype)

    def process_noise(self, dtype: torch.dtype) -> Tensor:
        """``Q (n', n')`` added over one prediction step."""
        return torch.diag(functional.softplus(self.process_raw).square()).to(dtype)

    def inputs(self, features: tuple[Tensor, Tensor, Tensor, Tensor]) -> tuple[Tensor, Tensor]:
        """The branches' inputs: ``[F3, F4] / p0`` and ``[F1, F2] / sqrt(diag S_ref)``, clipped to
        ``+-`` :data:`INPUT_CLIP`."""
        f1, f2, f3, f4 = features
        state = torch.cat((f3, f4), -1) / self.state_scale.to(f3).repeat(2)
        measurement = torch.cat((f1, f2), -1) / self.measurement_scale.to(f1).repeat(2)
        return state.clamp(-INPUT_CLIP, INPUT_CLIP), measurement.clamp(-INPUT_CLIP, INPUT_CLIP)

    # ------------------------------------------------------------------ steps (pure)
    def _start(self, mean: Tensor, last_measurement: Tensor) -> SplitKalmanNetState:
        batch = mean.shape[0]
        tangent = mean.new_zeros(batch, self.n)
        covariance = self.initial_covariance.to(mean).expand(batch, -1, -1)
        hidden = SplitHidden(self.state_branch.initial_hidden(batch), self.measurement_branch.initial_hidden(batch))
        return SplitKalmanNetState(mean, mean, tangent, tangent, last_measurement, covariance, hidden)

    def prior(self, batch: int, dtype: torch.dtype = torch.float64, device: torch.device | None = None) -> SplitKalmanNetState:
        """The state reported before a sequence's first usable measurement (covariance ``P_ref``)."""
        mean = self.model.prior_state(batch, dtype).to(device)  # (a model's prior is on the CPU)
        return self._start(mean, mean.new_zeros(batch, self.manifold.measurement_dim))

    def predict(self, state: SplitKalmanNetState, dt: float) -> SplitKalmanNetState:
        """Mean and reported covariance predicted over ``dt`` seconds (``P = F P F^T + Q``)."""
        predicted = self._propagator.predict(FilterState(state.mean, state.covariance),
                                             self.process_noise(state.mean.dtype), dt)
        covariance = predicted.covariance if self.covariance_is_trained else predicted.covariance.detach()
        return state._replace(mean=predicted.mean, covariance=covariance)

    def initial(self, state: SplitKalmanNetState, z: Tensor) -> SplitKalmanNetState:
        """The state initialised from usable measurements ``z (B, m)`` (``P_ref``, hidden states at zero)."""
        return self._start(self.model.initial_state(z), z)

    def update(self, state: SplitKalmanNetState, z: Tensor) -> SplitKalmanNetState:
        """The measurement update of every row with usable measurements ``z (B, m)``: ``x+ = x-
        [+] K dy`` (then the model's ``normalize``) and the reported covariance by the Joseph form."""
        prior = state.mean
        z = self.model.align(z, prior)
        features = self.features(state, z)
        state_in, measurement_in = self.inputs(features)
        state_raw, state_hidden = self.state_branch(state_in, state.hidden.state)
        measurement_raw, measurement_hidden = self.measurement_branch(measurement_in, state.hidden.measurement)
        P, K = self.prior_and_gain(state_raw.to(prior.dtype), measurement_raw.to(prior.dtype))
        innovation = features[1]
        delta = (K @ innovation[:, :, None])[:, :, 0]
        posterior = self.model.normalize(self.manifold.correct(prior, delta))[0]
        evolution = self.manifold.state_difference(posterior, state.last_posterior)
        gain = K
        if P is None:  # the covariance the gain implies: from the predicted one
            P = state.covariance
        if not self.covariance_is_trained:
            P, gain = P.detach(), K.detach()
        eye = torch.eye(self.n, dtype=prior.dtype, device=prior.device)
        covariance = joseph_update(P, gain, self.H.to(prior.dtype), self.measurement_noise(prior.dtype)) + self.std_floor**2 * eye
        return SplitKalmanNetState(posterior, posterior, evolution, delta, z, covariance,
                                   SplitHidden(state_hidden, measurement_hidden))

    # ------------------------------------------------------------------ sequences
    def run(self, measurements: Tensor, mask: Tensor, *, dt: float) -> SplitKalmanNetRun:
        """Filter a batch: ``measurements (B, T, m)`` (entries outside ``mask`` are ignored and
        may be NaN), ``mask (B, T)`` -> :class:`SplitKalmanNetRun`."""
        (means, covariances), updates, initialised, final = self.recurse(
            measurements, mask, dt=dt, record=lambda s: (s.mean, s.covariance))
        return SplitKalmanNetRun(means, covariances, updates, initialised, final)

    def describe(self) -> dict[str, Any]:
        return {
            "architecture": self.architecture,
            "process_model": type(self.model).__name__,
            "manifold": self.manifold.name,
            "state_tangent_dim": self.n,
            "measurement_tangent_dim": self.m,
            "in_mult": self.in_mult,
            "hidden_mult": self.hidden_mult,
            "out_mult": self.out_mult,
            "network_dtype": str(self.state_branch.dtype).removeprefix("torch."),
            "process_std": [float(v) for v in functional.softplus(self.process_raw.detach())],
            "weights": int(sum(p.numel() for p in self.parameters())),
        }
