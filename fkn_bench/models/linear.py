"""A linear-Gaussian model, ``x' = A x``, ``y = H x``: it reduces any filter to the textbook
Kalman filter (:func:`fkn_bench.filters.linear.linear_kalman_filter`); the tests hold the EKF and
the UKF to it."""

from __future__ import annotations

import numpy as np

from fkn_bench.linalg import constant, namespace
from fkn_bench.models.base import StateSpaceModel
from fkn_bench.types import Array
from fkn_bench.models.noise import NoiseLayout

__all__ = ["LinearGaussianModel"]


class LinearGaussianModel(StateSpaceModel):
    """``x' = A x``, ``y = H x`` (``A`` and ``H`` fixed matrices; ``dt`` is ignored).

    The layout labels components ``x0, x1, ...`` and ``y0, ...``; defaults are unit standard
    deviations. ``initial_state`` solves ``H x = z`` in the least-squares sense.
    """

    def __init__(self, A: Array, H: Array, *, layout: NoiseLayout | None = None) -> None:
        self.A, self.H = (np.array(a.detach().numpy() if hasattr(a, "detach") else a, dtype=np.float64) for a in (A, H))
        n, m = self.A.shape[0], self.H.shape[0]
        if self.A.shape != (n, n) or self.H.shape != (m, n):
            raise ValueError(f"A must be (n, n) and H (m, n); got {tuple(self.A.shape)} and {tuple(self.H.shape)}")
        self.state_dim, self.measurement_dim = n, m
        xs, ys = tuple(f"x{i}" for i in range(n)), tuple(f"y{i}" for i in range(m))
        default = NoiseLayout(xs, ("1",) * n, (1.0,) * n, ys, ("1",) * m, (1.0,) * m, xs, ("1",) * n, (1.0,) * n)
        self.layout = layout if layout is not None else default

    def transition(self, x: Array, dt: float) -> tuple[Array, Array]:
        A = constant(x, "A", lambda: self.A, self._constants())
        return x @ A.swapaxes(0, 1), namespace(x).broadcast_to(A, (x.shape[0],) + self.A.shape)

    def initial_state(self, z: Array) -> Array:
        return z @ constant(z, "pinv-H^T", lambda: np.linalg.pinv(self.H).T, self._constants())
