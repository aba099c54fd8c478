"""The interface every state-space model implements, written once for numpy arrays (online,
one sequence) and torch tensors (batched, differentiable).

A model tells a filter how the state moves (``transition``: the mean ``f(x)`` and its Jacobian
``F = df/dx``), what is measured (a linear ``H``; ``observed`` names the measured slice when
``H = [I 0]``), and how to keep states and measurements well-formed (``sanitize``, ``align``,
``normalize``). Filters (:mod:`fkn_bench.filters`) are generic over models; nothing in a filter
knows about quaternions except through these hooks. Every hook takes arrays with a leading batch
axis (``(B, n)`` states, ``(B, m)`` measurements) of either library and returns the same library's
arrays (:func:`fkn_bench.linalg.namespace`).

A model states what it offers (:attr:`StateSpaceModel.offers`), and filters ask for it by name,
never by the model's type: ``"pose-state"`` (the state begins ``[q(4), r(3), w(3), v(3)]``, so an
error-state filter may take a multiplicative attitude error), ``"structured-ekf"`` (the EKF may
run the compiled step of the 13-state constant-rate model, :mod:`fkn_bench.filters.structured`),
``"exact-rotation"`` (a constant world-frame rate: the attitude's exponential is exact over any
interval). A model that offers none is run by the generic code.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fkn_bench.linalg import constant, namespace
from fkn_bench.models.noise import NoiseLayout
from fkn_bench.types import Array, Bool, Float

__all__ = ["StateSpaceModel", "prior_array"]



class StateSpaceModel:
    """Interface of a model (see module docstring). Subclasses set the attributes below; ``H``
    is a float64 numpy array (:meth:`measurement_matrix` gives it in an array's namespace)."""

    state_dim: int
    measurement_dim: int
    H: np.ndarray
    observed: slice | None = None
    layout: NoiseLayout
    offers: frozenset[str] = frozenset()
    """What this model offers filters (module docstring): they test membership, never the type."""

    def _constants(self) -> dict:
        """This model's cache of constant arrays (see :func:`fkn_bench.linalg.constant`)."""
        return self.__dict__.setdefault("_cache", {})

    def predict(self, x: Float[Array, "B n"], dt: float) -> Float[Array, "B n"]:
        """Mean propagation ``f(x)`` of ``(B, n)`` states over ``dt`` seconds."""
        return self.transition(x, dt)[0]

    def jacobian(self, x: Float[Array, "B n"], dt: float) -> Float[Array, "B n n"]:
        """``F = df/dx`` ``(B, n, n)`` at ``x``."""
        return self.transition(x, dt)[1]

    def transition(self, x: Float[Array, "B n"], dt: float) -> tuple[Float[Array, "B n"], Float[Array, "B n n"]]:
        """``(f(x), F)`` together."""
        raise NotImplementedError

    def measurement_matrix(self, like: Array) -> Array:
        """``H (m, n)`` in the namespace and dtype of ``like``."""
        return constant(like, "H", lambda: self.H, self._constants())

    def measure(self, x: Float[Array, "B n"]) -> Float[Array, "B m"]:
        """``H x`` for states ``(B, n)``."""
        if self.observed is not None:
            return x[:, self.observed]
        return x @ self.measurement_matrix(x).swapaxes(0, 1)

    def sanitize(self, measurements: Float[Array, "... m"], mask: Bool[Array, "..."]) -> tuple[Float[Array, "... m"], Bool[Array, "..."]]:
        """Clean inputs once per sequence: drop non-finite measurements from the mask (zeros in
        their place)."""
        xp = namespace(measurements)
        mask = mask & xp.all(xp.isfinite(measurements), axis=-1)
        return xp.where(mask[..., None], measurements, 0.0), mask

    def align(self, z: Float[Array, "B m"], x_pred: Float[Array, "B n"]) -> Float[Array, "B m"]:
        """Measurement made comparable with the prediction (identity by default)."""
        return z

    def normalize(self, x: Array) -> tuple[Array, slice | None, Array | None]:
        """Posterior state projected onto the state's manifold, and the projection's Jacobian.

        The Jacobian is the identity except on one diagonal block: returns ``(x, block, N)``
        with ``N (B, b, b)`` the Jacobian on ``block`` (``None, None``: identity everywhere).
        """
        return x, None, None

    def null_direction(self, x: Array) -> Array | None:
        """Unit direction ``(B, n)`` that :meth:`normalize`'s projection removes from the
        covariance (``None``: none), so that square-root filters can regularise along it."""
        return None

    def initial_state(self, z: Float[Array, "B m"]) -> Float[Array, "B n"]:
        """State ``(B, n)`` initialised from measurements ``(B, m)``."""
        raise NotImplementedError

    def prior_state(self, batch: int, dtype: Any) -> Array:
        """State ``(B, n)`` reported before a sequence's first measurement (a CPU torch tensor
        for a torch ``dtype``, which the filters move to their inputs' device; else a numpy
        array)."""
        return prior_array(batch, self.state_dim, dtype, first=0.0)


def prior_array(batch: int, n: int, dtype: Any, *, first: float) -> Array:
    """``(B, n)`` zeros but ``first`` in the first column: a CPU torch tensor for a torch
    ``dtype``, else a numpy array."""
    x = np.zeros((batch, n))
    x[:, 0] = first
    if type(dtype).__module__.startswith("torch"):
        import torch

        return torch.from_numpy(x).to(dtype)
    return x.astype(dtype, copy=False)
