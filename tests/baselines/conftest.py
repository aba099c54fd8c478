"""Shared fixtures of the baseline tests."""

from __future__ import annotations

import pytest


# ---------------------------------------------------------------------------- linear CV models
class ConstantVelocity:
    """A 2-D constant-velocity model, ``x = [px, py, vx, vy]``, ``dt = 0.1``, position measured,
    with diagonal noise standard deviations ``q`` (4) and ``r`` (2), simulated in numpy."""

    dt = 0.1

    def __init__(self, q: tuple[float, ...], r: tuple[float, ...]) -> None:
        import numpy as np

        self.q, self.r = np.array(q), np.array(r)
        self.A = np.eye(4)
        self.A[0, 2] = self.A[1, 3] = self.dt
        self.H = np.eye(2, 4)

    @property
    def Q(self):  # noqa: ANN201
        import numpy as np

        return np.diag(self.q**2)

    @property
    def R(self):  # noqa: ANN201
        import numpy as np

        return np.diag(self.r**2)

    def simulate(self, batch: int, steps: int, seed: int):  # noqa: ANN201
        """``(truth (B, T, 4), measurements (B, T, 2))``."""
        import numpy as np

        rng = np.random.default_rng(seed)
        x = rng.normal(size=(batch, 4))
        truth, measured = np.empty((batch, steps, 4)), np.empty((batch, steps, 2))
        for t in range(steps):
            if t > 0:
                x = x @ self.A.T + rng.normal(size=(batch, 4)) * self.q
            truth[:, t] = x
            measured[:, t] = x @ self.H.T + rng.normal(size=(batch, 2)) * self.r
        return truth, measured

    def torch_model(self):  # noqa: ANN201
        import torch

        from fkn_bench.models import LinearGaussianModel

        return LinearGaussianModel(torch.from_numpy(self.A), torch.from_numpy(self.H))


SENSOR_LIMITED = ConstantVelocity(q=(0.02, 0.02, 0.2, 0.2), r=(0.5, 0.3))
"""Noisy sensor: ``R`` dominates the innovation covariance (R is well identified from it)."""
BALANCED = ConstantVelocity(q=(0.1, 0.08, 0.5, 0.4), r=(0.05, 0.08))
"""Process and measurement noise of comparable weight in the innovations (every standard
deviation identifiable by maximum likelihood)."""


@pytest.fixture(scope="session")
def sensor_limited() -> ConstantVelocity:
    return SENSOR_LIMITED


@pytest.fixture(scope="session")
def balanced() -> ConstantVelocity:
    return BALANCED
