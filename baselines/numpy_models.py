"""Batched numpy twins of the filter core's state-space models, for the adaptive filters.

The adaptive filters (:mod:`fkn_bench.baselines.adaptive`) run their recursion in numpy: their
noise updates (eigen-decompositions, inverse-Wishart fixed-point iterations) are not needed
differentiable, and torch's per-operation overhead would dominate one online step. They reach a
:class:`~fkn_bench.filters.models.StateSpaceModel` through the hooks below, on arrays with a
leading batch axis (``(B, n)`` states, ``(B, m)`` measurements), with the same rules as the
torch models:

* ``transition(x, dt) -> (f(x), F)``: mean propagation and its Jacobian;
* ``sanitize(z, mask) -> (z, usable)``: measurements cleaned once (non-finite ones dropped; the
  pose model also drops quaternions of norm below ``min_quaternion_norm`` and renormalises the
  rest);
* ``align(z, x_pred)``: the measurement made comparable with the prediction (the pose model
  flips the measured quaternion when ``z_q . q- < 0``);
* ``normalize(x) -> (x, block, N)``: the posterior projected onto the state manifold and the
  projection's Jacobian on one diagonal block (the pose model: unit quaternion,
  ``N = (I - u u^T) / |q|``);
* ``initial_state(z)``, ``prior_state(batch)``; ``H`` (``(m, n)``) and ``observed`` (the measured
  slice when ``H = [I 0]``, which turns products with ``H`` into slices).

:func:`numpy_model` picks the twin of a torch model: exact ones for
:class:`~fkn_bench.filters.models.PoseTwistModel` and
:class:`~fkn_bench.filters.models.LinearGaussianModel`, and for any other model a wrapper that
calls its torch hooks (generic, slower).
"""

from __future__ import annotations

import numpy as np
import torch

from fkn_bench.filters.models import LinearGaussianModel, PoseTwistModel, StateSpaceModel
from fkn_bench.filters.parameters import NoiseLayout
from fkn_bench.types import ArrayB, ArrayF

__all__ = ["NumpyModel", "NumpyPoseTwistModel", "NumpyLinearModel", "TorchModelAdapter", "numpy_model"]


class NumpyModel:
    """Interface of a batched numpy model (see module docstring)."""

    state_dim: int
    measurement_dim: int
    H: ArrayF
    observed: slice | None = None
    layout: NoiseLayout

    def transition(self, x: ArrayF, dt: float) -> tuple[ArrayF, ArrayF]:
        raise NotImplementedError

    def sanitize(self, z: ArrayF, mask: ArrayB) -> tuple[ArrayF, ArrayB]:
        """Default rule: measurements with a non-finite entry are unusable (zeros in their place)."""
        usable = mask & np.isfinite(z).all(-1)
        return np.where(usable[..., None], z, 0.0), usable

    def align(self, z: ArrayF, x_pred: ArrayF) -> ArrayF:
        return z

    def normalize(self, x: ArrayF) -> tuple[ArrayF, slice | None, ArrayF | None]:
        return x, None, None

    def initial_state(self, z: ArrayF) -> ArrayF:
        raise NotImplementedError

    def prior_state(self, batch: int) -> ArrayF:
        return np.zeros((batch, self.state_dim))

    def measure(self, x: ArrayF) -> ArrayF:
        """``H x`` for states ``(B, n)``."""
        if self.observed is not None:
            return x[:, self.observed]
        return x @ self.H.T


def _pose_row_basis() -> ArrayF:
    """``B (13, 52)`` with ``x @ B = [Omega(w) | 0 | Theta(q) | 0]`` (4 x 13, flattened): the
    quaternion rows of ``2 (F - A) / dt`` are linear in the state (FlexKalmanNet eqs. 8-11)."""
    basis = np.zeros((13, 4, 13))
    for i in range(4):
        w_, x_, y_, z_ = np.eye(4)[i]
        basis[i, :, 7:10] = ((-x_, -y_, -z_), (w_, z_, -y_), (-z_, w_, x_), (y_, -x_, w_))
    for i in range(3):
        a, b, c = np.eye(3)[i]
        basis[7 + i, :, 0:4] = ((0, -a, -b, -c), (a, 0, -c, b), (b, c, 0, -a), (c, -b, a, 0))
    return basis.reshape(13, 52)


_POSE_BASIS = _pose_row_basis()
_EYE4 = np.eye(4)


class NumpyPoseTwistModel(NumpyModel):
    """The paper's additive pose-and-twist model (:class:`~fkn_bench.filters.models.PoseTwistModel`)
    on batched numpy arrays: the same arithmetic as :mod:`fkn_bench.filters.online_ekf`."""

    state_dim = 13
    measurement_dim = 7
    observed = slice(0, 7)

    def __init__(self, *, min_quaternion_norm: float = 1e-6) -> None:
        self.min_quaternion_norm = float(min_quaternion_norm)
        self.H = np.concatenate((np.eye(7), np.zeros((7, 6))), axis=1)
        self.layout = PoseTwistModel.layout
        self._templates: dict[float, tuple[ArrayF, ArrayF, ArrayF]] = {}

    def _template(self, dt: float) -> tuple[ArrayF, ArrayF, ArrayF]:
        cached = self._templates.get(dt)
        if cached is None:
            if len(self._templates) >= 16:  # irregular online intervals must not grow the cache
                self._templates.clear()
            A = np.eye(13)
            A[4:7, 10:13] = dt * np.eye(3)
            cached = self._templates[dt] = (A, np.ascontiguousarray(A.T), (0.5 * dt) * _POSE_BASIS)
        return cached

    def transition(self, x: ArrayF, dt: float) -> tuple[ArrayF, ArrayF]:
        """``F = A + E`` with ``E = [dt/2 Omega(w) | 0 | dt/2 Theta(q) | 0]`` in the quaternion rows
        (``A``: identity plus ``r += dt v``), and ``f(x) = A x + dt/2 Omega(w) q``."""
        A, At, basis = self._template(float(dt))
        batch = x.shape[0]
        rows = (x @ basis).reshape(batch, 4, 13)
        x_pred = x @ At
        x_pred[:, 0:4] += (rows[:, :, 0:4] @ x[:, 0:4, None])[:, :, 0]
        F = np.empty((batch, 13, 13))
        F[:] = A
        F[:, 0:4] += rows
        return x_pred, F

    def sanitize(self, z: ArrayF, mask: ArrayB) -> tuple[ArrayF, ArrayB]:
        finite = np.isfinite(z).all(-1)
        if not finite.all():
            z = np.where(finite[..., None], z, 0.0)
        q = z[..., 0:4]
        if np.abs(q).max(initial=0.0) < 1e150:
            norm = np.sqrt((q * q).sum(-1))
        else:
            with np.errstate(over="ignore"):
                norm = np.sqrt((q * q).sum(-1))
        # a norm that overflows (components ~1e155 and up) leaves no usable direction either
        usable = mask & finite & (norm >= self.min_quaternion_norm) & np.isfinite(norm)
        out = np.where(usable[..., None], z, 0.0)
        out[..., 0:4] /= np.where(usable, norm, 1.0)[..., None]
        return out, usable

    def align(self, z: ArrayF, x_pred: ArrayF) -> ArrayF:
        dot = np.einsum("bi,bi->b", z[:, 0:4], x_pred[:, 0:4])
        if not (dot < 0.0).any():
            return z
        out = z.copy()
        out[:, 0:4] *= np.where(dot < 0.0, -1.0, 1.0)[:, None]
        return out

    def normalize(self, x: ArrayF) -> tuple[ArrayF, slice | None, ArrayF | None]:
        norm = np.sqrt(np.einsum("bi,bi->b", x[:, 0:4], x[:, 0:4]))[:, None]
        unit = x[:, 0:4] / norm
        out = x.copy()
        out[:, 0:4] = unit
        N = (_EYE4 - unit[:, :, None] * unit[:, None, :]) / norm[:, :, None]
        return out, slice(0, 4), N

    def initial_state(self, z: ArrayF) -> ArrayF:
        x = np.zeros((z.shape[0], 13))
        x[:, 0:7] = z
        return x

    def prior_state(self, batch: int) -> ArrayF:
        x = np.zeros((batch, 13))
        x[:, 0] = 1.0
        return x


class NumpyLinearModel(NumpyModel):
    """``x' = A x``, ``y = H x`` (:class:`~fkn_bench.filters.models.LinearGaussianModel`)."""

    def __init__(self, A: ArrayF, H: ArrayF, *, layout: NoiseLayout | None = None) -> None:
        self.A = np.array(A, dtype=float)
        self.H = np.array(H, dtype=float)
        n, m = self.A.shape[0], self.H.shape[0]
        if self.A.shape != (n, n) or self.H.shape != (m, n):
            raise ValueError(f"A must be (n, n) and H (m, n); got {self.A.shape} and {self.H.shape}")
        self.state_dim, self.measurement_dim = n, m
        self.layout = layout if layout is not None else LinearGaussianModel(torch.from_numpy(self.A), torch.from_numpy(self.H)).layout
        self._At = np.ascontiguousarray(self.A.T)
        self._pinv_t = np.linalg.pinv(self.H).T

    def transition(self, x: ArrayF, dt: float) -> tuple[ArrayF, ArrayF]:
        F = np.empty((x.shape[0],) + self.A.shape)
        F[:] = self.A
        return x @ self._At, F

    def initial_state(self, z: ArrayF) -> ArrayF:
        return z @ self._pinv_t


class TorchModelAdapter(NumpyModel):
    """Any torch :class:`StateSpaceModel` behind the numpy interface (converts at every call)."""

    def __init__(self, model: StateSpaceModel) -> None:
        self.model = model
        self.state_dim = self.model.state_dim
        self.measurement_dim = self.model.measurement_dim
        self.H = self.model.H.detach().to(torch.float64).numpy()
        self.observed = self.model.observed
        self.layout = self.model.layout

    def transition(self, x: ArrayF, dt: float) -> tuple[ArrayF, ArrayF]:
        with torch.no_grad():
            mean, F = self.model.transition(torch.from_numpy(np.ascontiguousarray(x)), dt)
        return mean.numpy().copy(), F.numpy().copy()

    def sanitize(self, z: ArrayF, mask: ArrayB) -> tuple[ArrayF, ArrayB]:
        with torch.no_grad():
            out, usable = self.model.sanitize(torch.from_numpy(np.ascontiguousarray(z)), torch.from_numpy(np.ascontiguousarray(mask)))
        return out.numpy().copy(), usable.numpy().copy()

    def align(self, z: ArrayF, x_pred: ArrayF) -> ArrayF:
        with torch.no_grad():
            return self.model.align(torch.from_numpy(np.ascontiguousarray(z)), torch.from_numpy(np.ascontiguousarray(x_pred))).numpy().copy()

    def normalize(self, x: ArrayF) -> tuple[ArrayF, slice | None, ArrayF | None]:
        with torch.no_grad():
            out, block, N = self.model.normalize(torch.from_numpy(np.ascontiguousarray(x)))
        return out.numpy().copy(), block, None if N is None else N.numpy().copy()

    def initial_state(self, z: ArrayF) -> ArrayF:
        with torch.no_grad():
            return self.model.initial_state(torch.from_numpy(np.ascontiguousarray(z))).numpy().copy()

    def prior_state(self, batch: int) -> ArrayF:
        return self.model.prior_state(batch, torch.float64).numpy().copy()


def numpy_model(model: StateSpaceModel | NumpyModel | None) -> NumpyModel:
    """The numpy twin of ``model`` (default: the paper's pose-and-twist model); models of other
    types (subclasses included) run through :class:`TorchModelAdapter`."""
    if model is None:
        return NumpyPoseTwistModel()
    if isinstance(model, NumpyModel):
        return model
    # exact types only: a subclass may override hooks that the twins do not know about
    if type(model) is PoseTwistModel:
        return NumpyPoseTwistModel(min_quaternion_norm=model.min_quaternion_norm)
    if type(model) is LinearGaussianModel:
        return NumpyLinearModel(model.A.numpy(), model.H.numpy(), layout=model.layout)
    if isinstance(model, StateSpaceModel):
        return TorchModelAdapter(model)
    raise TypeError(f"expected a StateSpaceModel (got {type(model).__name__})")
