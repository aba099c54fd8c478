"""Recursive KalmanNet: a learned gain and a learned, consistent error covariance.

H. Mortada, C. Falcon, Y. Kahil, M. Clavaud and J.-P. Michel, "Recursive KalmanNet: Deep
Learning-Augmented Kalman Filtering for State Estimation with Consistent Uncertainty
Quantification", EUSIPCO 2025 (arXiv:2506.11639). The filter keeps the Kalman filter's flow, as
KalmanNet does, with two recurrent networks fed the same features at every measurement update:

* the gain branch outputs the Kalman gain ``K_t`` (``n' x m'``);
* the covariance branch outputs a lower-triangular factor ``L_t`` (``n' (n' + 1) / 2`` entries),

and the error covariance is propagated by the recursive Joseph formula with the learned factor in
the place of ``K R K^T`` (the paper's "A + B")::

    P_t|t-1 = F P_t-1|t-1 F^T (+ Q, see the deviations)
    x_t|t   = x_t|t-1 [+] K_t dy_t
    P_t|t   = (I - K_t H) P_t|t-1 (I - K_t H)^T + L_t L_t^T (+ floor^2 I)

Training minimises the Gaussian negative log-likelihood of the true state under
``N(x_t|t, P_t|t)`` (``objective = "gaussian-nll"``, the paper's loss) or the MSE of the state
(``"supervised"``, KalmanNet's). Each branch is ``FC-in (ReLU) -> GRU -> FC-out (ReLU) ->
linear`` (:class:`GRUBranch`), its GRU's hidden state starting at zero for every sequence.

Conventions, as :mod:`fkn_bench.kalmannet.recursion` (KalmanNet's, whose pieces are reused: the
:class:`~fkn_bench.kalmannet.manifolds.Manifold`, the features, the batch loop, the state
layout): the pose state ``[q, r, w, v]`` (quaternion Hamilton, scalar first ``wxyz``, body to
world; SI units: rad, m, rad/s, m/s, world-frame rates) lives in its tangent space, so ``n' =
12`` and ``m' = 6``, differences are rotation vectors, the correction is ``Exp(dtheta) (x) q``,
measurements are sign-aligned with the prediction before they are differenced, and the posterior
quaternion is renormalised. The covariance ``P`` is that of the 12-dim error ``[dtheta, dr, dw,
dv]`` with ``q_true = Exp(dtheta) (x) q_est`` (world frame): the error covariance the estimators
report (:attr:`fkn_bench.estimators.Estimates.error_covariances`), so that the harness scores
its NEES; ``F`` is the multiplicative EKF's error transition over ``dt``
(:class:`~fkn_bench.filters.mekf.MultiplicativeEKF`, on any pose-twist process model: constant
rate or rigid body) and ``H = [I6 0]``. On another model (the Euclidean manifold) ``F`` is the
model's Jacobian (:class:`~fkn_bench.filters.ExtendedKalmanFilter`) and ``H`` its matrix.

Deviations from the paper (and its public code), each for a reason:

* Features: the paper feeds the squared innovation, observation difference, last correction and
  the (time-varying) measurement matrix ``H``. ``H`` is constant here and carries nothing;
  KalmanNet's forward-evolution difference F3 takes its place, so the input is ``[F1, F2, F3,
  F4]`` squared element-wise (the paper's transform, which keeps the magnitudes a covariance
  needs), each square clipped at ``1e6`` so that a gross outlier cannot overflow the network.
* Positive definite by construction: the factor's diagonal goes through a softplus and
  ``std_floor^2 I`` is added (the paper's ``L L^T`` is only semi-definite), so ``P >= floor^2 I``
  and its Cholesky factorisation, the NLL and the NEES are always defined.
* Sparse measurements: the paper measures every step. Here the prediction steps between two
  measurements (nine of ten in the benchmark) propagate ``P`` with ``F`` and, by default, a
  learned diagonal process noise ``Q = diag(s^2) dt`` (``process_std``: the starting ``s``;
  None: none, the paper's ``F P F^T``), so that the covariance reported between measurements can
  grow; the learned factor still stands in for everything else at the update.
* Size and initialisation: the paper's code widens each branch by 10 (FC-in), 10 (GRU) and 20
  (FC-out) per unit: 30 million weights on the pose model; the defaults here are 5, 2 and 2
  (0.45 million). The gain branch starts near half the observed gain and the covariance branch
  near ``initial_std`` on the diagonal (output weights scaled by ``output_scale``), as
  KalmanNet's deviation: untrained, on the ds1 test split (seed 0), PyTorch's default
  initialisation gives a 13-state RMSE of 3e26, this one 0.042.
* Initial covariance: ``P0`` is fixed, the multiplicative EKF's documented one
  (:data:`~fkn_bench.filters.mekf.MEKF_MANUAL_LAYOUT`; the identity on the Euclidean manifold);
  a sequence initialises at its first usable measurement as every estimator does.
* Gate: the paper's filter uses every measurement. Here, where no gradients are recorded, an
  innovation whose NIS under ``S = H P H^T + R`` (``R`` the manual tuning's, which the network
  does not learn) exceeds the 1 - 1e-6 chi-square quantile, or a correction a hundred times beyond any
  Kalman gain's under ``P`` (:meth:`~fkn_bench.kalmannet.recursion.ManifoldRecursion.plausible_correction`,
  :data:`~fkn_bench.kalmannet.recursion.CORRECTION_MARGIN`), is not used, and three such measurements in a row restart the track, the rule of the gated
  Kalman filters (:class:`~fkn_bench.kalmannet.recursion.NetworkSteps`). Without it the filter ran
  away wherever the test scenario left its training (a 13-state RMSE of 5e96 on spin-noise5x).
* The error covariance is not reset after the quaternion correction (the paper has no
  manifold; the reset's effect is second order in the correction).

One difference from KalmanNet's recursion: the mean is predicted together with the covariance,
by the multiplicative EKF's prediction step (the exact rotation over ``dt`` on the constant-rate
model, where KalmanNet takes the model's first-order ``predict``; the model's transition with the
quaternion renormalised on the rigid body), so that mean and covariance come from one transition.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import torch
from torch import Tensor, nn
from torch.nn import functional

from fkn_bench.filters import ExtendedKalmanFilter
from fkn_bench.filters.base import FilterState
from fkn_bench.filters.mekf import MEKF_MANUAL_LAYOUT, MultiplicativeEKF
from fkn_bench.models.base import StateSpaceModel
from fkn_bench.kalmannet.manifolds import Manifold, PoseTangent
from fkn_bench.kalmannet.recursion import ManifoldRecursion
from fkn_bench.linalg import symmetrize

__all__ = ["GRUBranch", "RecursiveHidden", "RecursiveKalmanNet", "RecursiveKalmanNetRun", "RecursiveKalmanNetState"]

FEATURE_CLIP = 1e6
"""Largest value of a squared feature entering the networks."""


def _inverse_softplus(y: float) -> float:
    return y + math.log(-math.expm1(-y))


class GRUBranch(nn.Module):
    """One branch of Recursive KalmanNet: ``FC-in (ReLU) -> GRU -> FC-out (ReLU) -> linear``.

    Args:
        inputs, outputs: sizes of the features and of the output.
        in_mult: FC-in width per input; hidden_mult: GRU hidden size per output; out_mult:
            FC-out width per hidden unit (the paper's code: 10, 10, 20).
        dtype: the branch's dtype.
        output_bias: ``(outputs,)`` bias of the output layer (None: PyTorch's default).
        output_scale: factor on the output layer's weights at initialisation.
    """

    def __init__(
        self,
        inputs: int,
        outputs: int,
        *,
        in_mult: int = 5,
        hidden_mult: int = 2,
        out_mult: int = 2,
        dtype: torch.dtype = torch.float32,
        output_bias: Tensor | None = None,
        output_scale: float = 1.0,
    ) -> None:
        super().__init__()
        if min(inputs, outputs, in_mult, hidden_mult, out_mult) < 1:
            raise ValueError(f"sizes and multipliers must be >= 1 (got {inputs}, {outputs}, {in_mult}, {hidden_mult}, {out_mult})")
        width, hidden = inputs * in_mult, outputs * hidden_mult
        self.fc_in = nn.Sequential(nn.Linear(inputs, width), nn.ReLU())
        self.gru = nn.GRUCell(width, hidden)
        self.fc_out = nn.Sequential(nn.Linear(hidden, hidden * out_mult), nn.ReLU(), nn.Linear(hidden * out_mult, outputs))
        with torch.no_grad():
            last = self.fc_out[-1]
            last.weight.mul_(output_scale)
            if output_bias is not None:
                if tuple(output_bias.shape) != (outputs,):
                    raise ValueError(f"output_bias must be ({outputs},) (got {tuple(output_bias.shape)})")
                last.bias.copy_(output_bias)
        self.register_buffer("prior_hidden", torch.zeros(hidden))
        self.to(dtype)

    @property
    def dtype(self) -> torch.dtype:
        return self.prior_hidden.dtype

    def initial_hidden(self, batch: int) -> Tensor:
        """The GRU's hidden state at a sequence's start (zeros, as the paper's code)."""
        return self.prior_hidden.expand(batch, -1)

    def forward(self, features: Tensor, hidden: Tensor) -> tuple[Tensor, Tensor]:
        """``features (B, inputs)`` and ``hidden`` -> ``(output (B, outputs), next hidden)``."""
        hidden = self.gru(self.fc_in(features.to(self.dtype)), hidden)
        return self.fc_out(hidden), hidden


class RecursiveHidden(NamedTuple):
    """The two branches' GRU hidden states, ``gain (B, n' m' hidden_mult)`` and ``covariance
    (B, n' (n' + 1) / 2 hidden_mult)`` (network dtype)."""

    gain: Tensor
    covariance: Tensor


class RecursiveKalmanNetState(NamedTuple):
    """A batch of Recursive KalmanNet states at one time: KalmanNet's fields
    (:class:`~fkn_bench.kalmannet.KalmanNetState`: ``mean``, ``last_posterior``, ``evolution``,
    ``correction``, ``last_measurement``) and ``covariance (B, n', n')``, the error covariance in
    tangent coordinates (see module docstring), and the branches' ``hidden`` states."""

    mean: Tensor
    last_posterior: Tensor
    evolution: Tensor
    correction: Tensor
    last_measurement: Tensor
    covariance: Tensor
    hidden: RecursiveHidden


class RecursiveKalmanNetRun(NamedTuple):
    """Result of :meth:`RecursiveKalmanNet.run` (batch first): ``means (B, T, n)``,
    ``covariances (B, T, n', n')``, ``updated (B, T)``, ``initialised (B, T)``, ``final``."""

    means: Tensor
    covariances: Tensor
    updated: Tensor
    initialised: Tensor
    final: RecursiveKalmanNetState


class RecursiveKalmanNet(ManifoldRecursion):
    """Recursive KalmanNet on a state-space model (see module docstring).

    Args:
        model: the process and measurement model; on the pose tangent space a pose-twist model
            (:class:`~fkn_bench.models.pose_twist.PoseTwistModel` or the rigid body), whose error
            transition the multiplicative EKF forms.
        manifold: ``"auto"``, ``"pose-tangent"`` or ``"euclidean"``; or a :class:`Manifold`.
        in_mult, hidden_mult, out_mult: the branches' widths (:class:`GRUBranch`).
        network_dtype: the branches' dtype (the covariance arithmetic runs in the measurements').
        detach_every: truncated back-propagation through time (as KalmanNet's).
        initial_gain: the gain branch's output bias is ``initial_gain * G`` (``G`` the manifold's
            observed gain; None: PyTorch's default).
        output_scale: factor on both branches' output weights at initialisation.
        initial_std: the covariance branch's factor starts near ``initial_std I``.
        std_floor: ``std_floor^2 I`` is added to every posterior covariance.
        process_std: starting value of the learned diagonal process noise density (None: none).
    """

    objectives = ("gaussian-nll", "supervised")
    architecture = "Recursive KalmanNet (Mortada et al., EUSIPCO 2025)"

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
        initial_gain: float | None = 0.5,
        output_scale: float = 0.1,
        initial_std: float = 0.01,
        std_floor: float = 1e-4,
        process_std: float | None = 1e-3,
    ) -> None:
        super().__init__(model, manifold=manifold, detach_every=detach_every)
        if not (initial_std > 0 and std_floor > 0):
            raise ValueError(f"initial_std and std_floor must be > 0 (got {initial_std}, {std_floor})")
        n, m = self.manifold.state_tangent_dim, self.manifold.measurement_tangent_dim
        self.n, self.m, self.std_floor = n, m, float(std_floor)
        self.in_mult, self.hidden_mult, self.out_mult = int(in_mult), int(hidden_mult), int(out_mult)
        inputs = 2 * m + 2 * n  # F1, F2 (m'), F3, F4 (n')
        gain_bias = None if initial_gain is None else initial_gain * torch.from_numpy(self.manifold.observed_gain()).reshape(-1)
        self.gain_branch = GRUBranch(inputs, n * m, in_mult=in_mult, hidden_mult=hidden_mult, out_mult=out_mult,
                                     dtype=network_dtype, output_bias=gain_bias, output_scale=output_scale)
        rows, cols = torch.tril_indices(n, n)
        factor_bias = torch.where(rows == cols, _inverse_softplus(initial_std), 0.0).to(torch.float64)
        self.covariance_branch = GRUBranch(inputs, rows.numel(), in_mult=in_mult, hidden_mult=hidden_mult,
                                           out_mult=out_mult, dtype=network_dtype, output_bias=factor_bias,
                                           output_scale=output_scale)
        self.register_buffer("tril_rows", rows, persistent=False)
        self.register_buffer("tril_cols", cols, persistent=False)
        self.register_buffer("diagonal", rows == cols, persistent=False)
        if isinstance(self.manifold, PoseTangent):
            p0 = torch.tensor(MEKF_MANUAL_LAYOUT.p0_default, dtype=torch.float64).square().diag()
            self._propagator: Any = MultiplicativeEKF(model=model)  # the error transition of the pose state
        else:
            p0 = torch.eye(n, dtype=torch.float64)
            self._propagator = ExtendedKalmanFilter(model=model)
        self.register_buffer("initial_covariance", p0, persistent=False)
        self.process_raw = None if process_std is None else nn.Parameter(torch.full((n,), _inverse_softplus(process_std),
                                                                                    dtype=torch.float64))

    # ------------------------------------------------------------------ pieces
    @property
    def gated(self) -> bool:  # type: ignore[override]
        """On the pose tangent space (the gate's ``R``: :meth:`~ManifoldRecursion.measurement_noise`)."""
        return isinstance(self.manifold, PoseTangent)

    def process_noise(self, dt: float, dtype: torch.dtype) -> Tensor:
        """``Q (n', n')`` added over a prediction of ``dt`` seconds (zeros without process noise),
        on the module's device."""
        if self.process_raw is None:
            return self.initial_covariance.new_zeros(self.n, self.n, dtype=dtype)
        return torch.diag(functional.softplus(self.process_raw).square() * dt).to(dtype)

    def factor(self, raw: Tensor) -> Tensor:
        """The lower-triangular factor ``(B, n', n')`` of the covariance branch's output ``(B, n'
        (n' + 1) / 2)`` (row-major lower triangle): softplus on the diagonal."""
        values = torch.where(self.diagonal, functional.softplus(raw), raw)
        L = raw.new_zeros(raw.shape[0], self.n, self.n)
        L[:, self.tril_rows, self.tril_cols] = values
        return L

    def network_features(self, features: tuple[Tensor, ...]) -> Tensor:
        """The branches' input: ``[F1, F2, F3, F4]`` squared element-wise, clipped at :data:`FEATURE_CLIP`."""
        return torch.cat(features, dim=-1).square().clamp(max=FEATURE_CLIP)

    # ------------------------------------------------------------------ steps (pure)
    def _start(self, mean: Tensor, last_measurement: Tensor) -> RecursiveKalmanNetState:
        batch = mean.shape[0]
        tangent = mean.new_zeros(batch, self.n)
        covariance = self.initial_covariance.to(mean.dtype).expand(batch, -1, -1)
        hidden = RecursiveHidden(self.gain_branch.initial_hidden(batch), self.covariance_branch.initial_hidden(batch))
        return RecursiveKalmanNetState(mean, mean, tangent, tangent, last_measurement, covariance, hidden)

    def prior(self, batch: int, dtype: torch.dtype = torch.float64, device: torch.device | None = None) -> RecursiveKalmanNetState:
        """The state reported before a sequence's first usable measurement (covariance ``P0``)."""
        mean = self.model.prior_state(batch, dtype).to(device)  # (a model's prior is on the CPU)
        return self._start(mean, mean.new_zeros(batch, self.manifold.measurement_dim))

    def predict(self, state: RecursiveKalmanNetState, dt: float) -> RecursiveKalmanNetState:
        """Mean and covariance predicted over ``dt`` seconds (``P = F P F^T + Q``); memories unchanged."""
        predicted = self._propagator.predict(FilterState(state.mean, state.covariance),
                                             self.process_noise(dt, state.mean.dtype), dt)
        return state._replace(mean=predicted.mean, covariance=predicted.covariance)

    def initial(self, state: RecursiveKalmanNetState, z: Tensor) -> RecursiveKalmanNetState:
        """The state initialised from usable measurements ``z (B, m)`` (``P0``, hidden states at zero)."""
        return self._start(self.model.initial_state(z), z)

    def update(self, state: RecursiveKalmanNetState, z: Tensor) -> RecursiveKalmanNetState:
        """The measurement update of every row with usable measurements ``z (B, m)``:
        ``x+ = x- [+] K dy`` (then the model's ``normalize``) and the Joseph form with the
        learned factor (module docstring)."""
        prior = state.mean
        z = self.model.align(z, prior)
        f1, innovation, f3, f4 = self.features(state, z)
        inputs = self.network_features((f1, innovation, f3, f4))
        gain, gain_hidden = self.gain_branch(inputs, state.hidden.gain)
        raw, covariance_hidden = self.covariance_branch(inputs, state.hidden.covariance)
        K = gain.to(prior.dtype).reshape(-1, self.n, self.m)
        L = self.factor(raw.to(prior.dtype))
        delta = (K @ innovation[:, :, None])[:, :, 0]
        posterior = self.model.normalize(self.manifold.correct(prior, delta))[0]
        evolution = self.manifold.state_difference(posterior, state.last_posterior)
        eye = torch.eye(self.n, dtype=prior.dtype, device=prior.device)
        IKH = eye - K @ self.H.to(prior.dtype)
        P = IKH @ state.covariance @ IKH.transpose(1, 2) + L @ L.transpose(1, 2) + self.std_floor**2 * eye
        return RecursiveKalmanNetState(posterior, posterior, evolution, delta, z, symmetrize(P),
                                       RecursiveHidden(gain_hidden, covariance_hidden))

    # ------------------------------------------------------------------ sequences
    def run(self, measurements: Tensor, mask: Tensor, *, dt: float) -> RecursiveKalmanNetRun:
        """Filter a batch: ``measurements (B, T, m)`` (entries outside ``mask`` are ignored and
        may be NaN), ``mask (B, T)`` -> :class:`RecursiveKalmanNetRun`."""
        (means, covariances), updates, initialised, final = self.recurse(
            measurements, mask, dt=dt, record=lambda s: (s.mean, s.covariance))
        return RecursiveKalmanNetRun(means, covariances, updates, initialised, final)

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
            "network_dtype": str(self.gain_branch.dtype).removeprefix("torch."),
            "process_std": None if self.process_raw is None
            else [float(v) for v in functional.softplus(self.process_raw.detach())],
            "weights": int(sum(p.numel() for p in self.parameters())),
        }
