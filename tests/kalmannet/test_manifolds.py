"""KalmanNet's differences and corrections: sign-safe in the pose tangent space, inverse to
each other, finite for the zero placeholder of a missing measurement."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fkn_bench.models import LinearGaussianModel, PoseTwistModel
from fkn_bench.kalmannet import Euclidean, PoseTangent, manifold_for


def _states(seed: int, batch: int = 6) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    x = torch.randn(batch, 13, generator=g, dtype=torch.float64)
    x[:, :4] /= x[:, :4].norm(dim=1, keepdim=True)
    return x


def test_pose_differences_do_not_depend_on_quaternion_signs() -> None:
    manifold = PoseTangent()
    a, b = _states(0), _states(1)
    flip = lambda x: torch.cat((-x[:, :4], x[:, 4:]), 1)  # noqa: E731
    reference = manifold.state_difference(a, b)
    assert reference.shape == (6, 12)
    for u, v in ((flip(a), b), (a, flip(b)), (flip(a), flip(b))):
        assert torch.equal(manifold.state_difference(u, v), reference)
    za, zb = a[:, :7], b[:, :7]
    assert torch.equal(manifold.measurement_difference(flip(za), zb), manifold.measurement_difference(za, zb))


def test_pose_correction_inverts_the_difference() -> None:
    manifold = PoseTangent()
    a, b = _states(2), _states(3)
    moved = manifold.correct(b, manifold.state_difference(a, b))
    same_sign = torch.where((moved[:, :4] * a[:, :4]).sum(1, keepdim=True) < 0, -moved[:, :4], moved[:, :4])
    torch.testing.assert_close(same_sign, a[:, :4], rtol=0, atol=1e-12)
    torch.testing.assert_close(moved[:, 4:], a[:, 4:], rtol=0, atol=1e-12)
    # the attitude correction is a world-frame rotation: Exp(dtheta) (x) q
    delta = torch.zeros(1, 12, dtype=torch.float64)
    delta[0, 2] = np.pi / 2
    q = manifold.correct(torch.eye(1, 13, dtype=torch.float64), delta)[0, :4]
    torch.testing.assert_close(q, torch.tensor([np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)], dtype=torch.float64))


def test_zero_placeholders_give_finite_values_and_gradients() -> None:
    manifold = PoseTangent()
    z = torch.zeros(2, 7, dtype=torch.float64, requires_grad=True)
    out = manifold.measurement_difference(z, _states(4, 2)[:, :7])
    out.sum().backward()
    assert torch.isfinite(out).all() and torch.isfinite(z.grad).all()


def test_the_manifold_follows_the_model() -> None:
    assert isinstance(manifold_for(PoseTwistModel()), PoseTangent)
    linear = LinearGaussianModel(np.eye(3), np.eye(2, 3))
    euclidean = manifold_for(linear)
    assert isinstance(euclidean, Euclidean) and (euclidean.state_tangent_dim, euclidean.measurement_tangent_dim) == (3, 2)
    np.testing.assert_allclose(linear.H @ euclidean.observed_gain(), np.eye(2), atol=1e-12)
    assert isinstance(manifold_for(PoseTwistModel(), "euclidean"), Euclidean)
    with pytest.raises(ValueError, match="13 states and 7 measurements"):
        manifold_for(linear, "pose-tangent")
