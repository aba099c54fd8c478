"""State-space models: the paper's pose-twist model (f, analytic Jacobian, hooks) and the
linear model."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch.autograd.functional import jacobian

from fkn_bench.models import LinearGaussianModel, PoseTwistModel
from fkn_bench.models import PAPER_MANUAL_LAYOUT
from fkn_bench.geometry import quaternion as quat
from fkn_bench.types import MEASUREMENT_NAMES, STATE_NAMES


def _random_states(seed: int, batch: int, *, unit: bool = True) -> torch.Tensor:
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((batch, 13))
    if unit:
        x[:, :4] /= np.linalg.norm(x[:, :4], axis=1, keepdims=True)
    x[:, 7:10] *= 0.5  # rad/s
    return torch.from_numpy(x)


def _paper_f(x: np.ndarray, dt: float) -> np.ndarray:
    """FlexKalmanNet eqs. 8-11 written out independently: q' = q + dt/2 Theta(q) w."""
    out = x.copy()
    out[0:4] = x[0:4] + 0.5 * dt * quat.theta_matrix(x[0:4]) @ x[7:10]
    out[4:7] = x[4:7] + dt * x[10:13]
    return out


# ---------------------------------------------------------------------------- predict / Jacobian
@pytest.mark.parametrize("dt", [0.1, 0.013, 1.7])
@pytest.mark.parametrize("unit", [True, False])
def test_jacobian_equals_autograd(dt: float, unit: bool) -> None:
    model = PoseTwistModel()
    x = _random_states(seed=int(dt * 1000) + unit, batch=6, unit=unit)
    analytic = model.jacobian(x, dt)
    assert analytic.shape == (6, 13, 13)
    for b in range(x.shape[0]):
        auto = jacobian(lambda s: model.predict(s[None], dt)[0], x[b])
        torch.testing.assert_close(analytic[b], auto, rtol=0, atol=1e-14)


def test_predict_matches_paper_equations() -> None:
    model = PoseTwistModel()
    x = _random_states(seed=3, batch=5)
    moved = model.predict(x, 0.1).numpy()
    for b in range(5):
        np.testing.assert_allclose(moved[b], _paper_f(x[b].numpy(), 0.1), rtol=0, atol=1e-15)
    # w and v are constant; r moves with v
    # exact: identity rows of A (products with 1 and 0, sums with 0)
    np.testing.assert_array_equal(moved[:, 7:13], x[:, 7:13].numpy())


def test_jacobian_float32_and_dtype() -> None:
    model = PoseTwistModel()
    x = _random_states(seed=4, batch=3)
    F32 = model.jacobian(x.float(), 0.1)
    assert F32.dtype == torch.float32
    torch.testing.assert_close(F32.double(), model.jacobian(x, 0.1), rtol=0, atol=1e-6)


# ---------------------------------------------------------------------------- hooks
def test_sanitize_rules() -> None:
    model = PoseTwistModel()
    z = torch.tensor(
        [
            [[2.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0],  # non-unit: renormalised
             [float("nan")] * 7,  # NaN inside the mask: dropped
             [0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0],  # zero quaternion: dropped
             [1.0, 0.0, 0.0, 0.0, float("inf"), 0.0, 0.0],  # inf: dropped
             [float("nan")] * 7,  # outside the mask
             [0.0, 3.0, 4.0, 0.0, -1.0, -2.0, -3.0]]  # norm 5
        ],
        dtype=torch.float64,
    )
    mask = torch.tensor([[True, True, True, True, False, True]])
    clean, usable = model.sanitize(z, mask)
    assert usable.tolist() == [[True, False, False, False, False, True]]
    assert torch.isfinite(clean).all()
    torch.testing.assert_close(clean[0, 0], torch.tensor([1.0, 0, 0, 0, 1, 2, 3], dtype=torch.float64))
    torch.testing.assert_close(clean[0, 5], torch.tensor([0.0, 0.6, 0.8, 0, -1, -2, -3], dtype=torch.float64))
    assert (clean[0, 1:5] == 0).all()


def test_sanitize_drops_quaternions_whose_norm_overflows() -> None:
    """|q|^2 overflows for components ~1e160: the quaternion carries no usable direction after
    the division by an infinite norm, so the update is skipped (not applied with q = 0)."""
    model = PoseTwistModel()
    z = torch.tensor([[[1e160, 1e160, 0.0, 0.0, 0.0, 0.0, 0.0], [1e150, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]]], dtype=torch.float64)
    clean, usable = model.sanitize(z, torch.ones(1, 2, dtype=torch.bool))
    assert usable.tolist() == [[False, True]]
    torch.testing.assert_close(clean[0, 1, :4], torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=torch.float64))


def test_align_flips_only_opposing_quaternions() -> None:
    model = PoseTwistModel()
    x = _random_states(seed=5, batch=8)
    z = torch.cat((x[:, :4], x[:, 4:7] + 0.1), dim=1)
    z[::2, :4] *= -1
    aligned = model.align(z, x)
    # exact: multiplying by +-1 (twice for the flipped rows) is exact
    torch.testing.assert_close(aligned[:, :4], x[:, :4], rtol=0, atol=0)
    torch.testing.assert_close(aligned[:, 4:], z[:, 4:], rtol=0, atol=0)


def test_normalize_returns_unit_quaternion_and_its_jacobian() -> None:
    model = PoseTwistModel()
    x = _random_states(seed=6, batch=4, unit=False)
    unit, block, N = model.normalize(x)
    assert block == slice(0, 4)
    torch.testing.assert_close(unit[:, :4].norm(dim=1), torch.ones(4, dtype=torch.float64))
    torch.testing.assert_close(unit[:, 4:], x[:, 4:], rtol=0, atol=0)  # exact: copied
    for b in range(4):
        auto = jacobian(lambda q: q / q.norm(), x[b, :4])
        torch.testing.assert_close(N[b], auto, rtol=0, atol=1e-14)
    direction = model.null_direction(x)
    assert direction is not None
    torch.testing.assert_close(direction[:, :4], unit[:, :4])
    assert (direction[:, 4:] == 0).all()
    # the projection removes the null direction
    torch.testing.assert_close(N @ unit[:, :4, None], torch.zeros(4, 4, 1, dtype=torch.float64), rtol=0, atol=1e-15)


def test_initial_and_prior_states() -> None:
    model = PoseTwistModel()
    z = torch.tensor([[0.5, 0.5, 0.5, 0.5, 1.0, 2.0, 3.0]], dtype=torch.float64)
    x0 = model.initial_state(z)
    torch.testing.assert_close(x0[0, :7], z[0])
    assert (x0[0, 7:] == 0).all()
    prior = model.prior_state(3, torch.float32)
    assert prior.dtype == torch.float32 and prior.shape == (3, 13)
    assert prior[:, 0].tolist() == [1.0] * 3 and (prior[:, 1:] == 0).all()


def test_paper_manual_layout() -> None:
    layout = PAPER_MANUAL_LAYOUT
    assert layout.q_labels == STATE_NAMES and layout.r_labels == MEASUREMENT_NAMES
    # FlexKalmanNet section 4.3: sigma_R = 0.1; sigma_Q = 0.005 for q and w, 1e-4 for r and v
    assert layout.r_default == (0.1,) * 7
    q = dict(zip(layout.q_labels, layout.q_default))
    assert all(q[k] == 0.005 for k in ("qw", "qx", "qy", "qz", "wx", "wy", "wz"))
    assert all(q[k] == 1e-4 for k in ("rx", "ry", "rz", "vx", "vy", "vz"))
    noise = layout.default_noise()
    torch.testing.assert_close(noise.measurement, 0.01 * torch.eye(7, dtype=torch.float64))


# ---------------------------------------------------------------------------- linear model
def test_linear_model() -> None:
    A = torch.tensor([[1.0, 0.1], [0.0, 1.0]])
    H = torch.tensor([[1.0, 0.0]])
    model = LinearGaussianModel(A, H)
    assert (model.state_dim, model.measurement_dim) == (2, 1)
    x = torch.tensor([[1.0, 2.0], [3.0, -1.0]], dtype=torch.float64)
    torch.testing.assert_close(model.predict(x, 123.0), x @ A.double().T)
    torch.testing.assert_close(model.jacobian(x, 0.1), A.double().expand(2, 2, 2))
    torch.testing.assert_close(model.initial_state(torch.tensor([[4.0]], dtype=torch.float64)), torch.tensor([[4.0, 0.0]], dtype=torch.float64))
    assert model.layout.q_labels == ("x0", "x1") and model.layout.r_labels == ("y0",)
    with pytest.raises(ValueError, match=r"A must be \(n, n\) and H \(m, n\)"):
        LinearGaussianModel(torch.ones(2, 3), H)
    with pytest.raises(ValueError, match=r"A must be \(n, n\) and H \(m, n\)"):
        LinearGaussianModel(A, torch.ones(1, 3))


def test_sanitize_drops_positions_beyond_the_plausible_limit() -> None:
    """A position component over ``max_abs_position`` (1e9 m by default) is not a measurement of
    anything: dropped, batched and online alike (its square would overflow the filters later)."""
    model = PoseTwistModel()
    z = np.array([[[1.0, 0, 0, 0, 1e9, 0, 0], [1.0, 0, 0, 0, 0, -1.01e9, 0], [1.0, 0, 0, 0, 0, 0, 1e300]]])
    _, usable = model.sanitize(z, np.ones((1, 3), dtype=bool))
    assert usable.tolist() == [[True, False, False]]
    _, usable_torch = model.sanitize(torch.from_numpy(z), torch.ones(1, 3, dtype=torch.bool))
    assert usable_torch.tolist() == [[True, False, False]]
    for row, expected in zip(z[0], (True, False, False)):
        assert bool(model.sanitize(row[None], np.ones(1, dtype=bool))[1][0]) is expected
    assert PoseTwistModel(max_abs_position=10.0).sanitize(z[0, :1], np.ones(1, dtype=bool))[1].tolist() == [False]
    with pytest.raises(ValueError, match="max_abs_position"):
        PoseTwistModel(max_abs_position=float("nan"))
