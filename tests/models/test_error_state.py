"""The error-state transition of a pose model: held to autograd through the attitude error."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fkn_bench.geometry import quaternion as qx
from fkn_bench.models import PoseTwistModel
from fkn_bench.models.error_state import error_transition
from fkn_bench.models.rigid_body import RigidBodyModel

DT = 0.1


def _plus(x: torch.Tensor, delta: torch.Tensor) -> torch.Tensor:
    """``x (+) delta``: ``q <- exp(dtheta / 2) (x) q``, the other components added."""
    q = qx.multiply(qx.from_rotation_vector(delta[None, 0:3]), x[None, 0:4])[0]
    return torch.cat((q, x[4:] + delta[3:]))


def _minus(y: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """``y (-) x``: the error ``delta`` with ``y = x (+) delta``."""
    dq = qx.multiply(y[None, 0:4], qx.conjugate(x[None, 0:4]))[0]
    return torch.cat((2.0 * dq[1:4] / dq[0], y[4:] - x[4:]))  # 2 vec / w: first-order exact at 0


@pytest.mark.parametrize("kind", ["constant-rate", "rigid-body-ratios"])
def test_error_transition_equals_autograd(kind: str) -> None:
    model = PoseTwistModel() if kind == "constant-rate" else RigidBodyModel(inertia=(1.0, 1.6, 2.1), estimate_ratios=True)
    generator = torch.Generator().manual_seed(3)
    x = 0.4 * torch.randn(4, model.state_dim, generator=generator, dtype=torch.float64)
    x[:, :4] = x[:, :4] / x[:, :4].norm(dim=1, keepdim=True)
    mean, Phi = error_transition(model, x, DT)
    n = model.state_dim - 1
    assert Phi.shape == (4, n, n)
    for row in range(x.shape[0]):
        base = error_transition(model, x[row : row + 1], DT)[0][0]
        expected = torch.autograd.functional.jacobian(
            lambda d: _minus(error_transition(model, _plus(x[row], d)[None], DT)[0][0], base), torch.zeros(n, dtype=torch.float64))
        np.testing.assert_allclose(Phi[row].numpy(), expected.numpy(), rtol=0, atol=1e-9)
        np.testing.assert_allclose(mean[row].numpy(), base.numpy(), rtol=0, atol=1e-15)


def test_numpy_and_torch_agree_and_a_non_pose_model_is_refused() -> None:
    model = PoseTwistModel()
    x = np.array([[0.5, 0.5, 0.5, 0.5, 1.0, 2.0, 3.0, 0.1, -0.2, 0.3, 0.01, 0.02, 0.03]])
    mean, Phi = error_transition(model, x, DT)
    mean_t, Phi_t = error_transition(model, torch.from_numpy(x), DT)
    np.testing.assert_allclose(Phi, Phi_t.numpy(), rtol=0, atol=1e-15)
    np.testing.assert_allclose(mean, mean_t.numpy(), rtol=0, atol=1e-15)
    from fkn_bench.models import LinearGaussianModel

    with pytest.raises(ValueError, match="pose-twist state"):
        error_transition(LinearGaussianModel(np.eye(2), np.eye(2)), np.zeros((1, 2)), DT)
