"""The torque-free rigid-body process model: Jacobian, truth, parametrisation and filters."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fkn_bench.envs.dynamics import FreeTumble
from fkn_bench.filters import ExtendedKalmanFilter, MultiplicativeEKF, UnscentedKalmanFilter
from fkn_bench.models import PoseTwistModel, make_model
from fkn_bench.models.rigid_body import (
    RigidBodyModel,
    euler_coefficients,
    inertia_ratios,
    moments_from_ratios,
)
from fkn_bench.scenarios import ASTROBEE_INERTIA

MODELS = {
    "known": lambda: RigidBodyModel(inertia=ASTROBEE_INERTIA),
    "ratios": lambda: RigidBodyModel(estimate_ratios=True),
    "ratios-3-substeps": lambda: RigidBodyModel(inertia=(1.0, 2.0, 2.5), estimate_ratios=True, substeps=3),
}


def _states(model: RigidBodyModel, batch: int = 5, seed: int = 0) -> torch.Tensor:
    generator = torch.Generator().manual_seed(seed)
    x = 0.3 * torch.randn(batch, model.state_dim, generator=generator, dtype=torch.float64)
    x[:, :4] = x[:, :4] / x[:, :4].norm(dim=1, keepdim=True) * 1.02  # not quite unit, as between updates
    return x


@pytest.mark.parametrize("kind", sorted(MODELS))
def test_analytic_jacobian_equals_autograd(kind: str) -> None:
    model = MODELS[kind]()
    x = _states(model)
    _, F = model.transition(x, 0.1)
    for row in range(x.shape[0]):
        expected = torch.autograd.functional.jacobian(lambda s: model.predict(s[None], 0.1)[0], x[row])
        torch.testing.assert_close(F[row], expected, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("kind", sorted(MODELS))
def test_numpy_and_torch_agree_batched_and_one_row(kind: str) -> None:
    model = MODELS[kind]()
    x = _states(model)
    mean, F = model.transition(x.clone().requires_grad_(), 0.1)  # the batched torch operations (under autograd)
    mean_np, F_np = model.transition(x.numpy(), 0.1)  # the compiled kernel
    np.testing.assert_allclose(mean_np, mean.detach().numpy(), rtol=0, atol=1e-14)
    np.testing.assert_allclose(F_np, F.detach().numpy(), rtol=0, atol=1e-13)
    mean_row, F_row = model.transition(x.numpy()[2:3], 0.1)
    np.testing.assert_allclose(mean_row, mean_np[2:3], rtol=0, atol=1e-15)
    np.testing.assert_allclose(F_row, F_np[2:3], rtol=0, atol=1e-15)


def test_prediction_follows_the_simulated_free_tumble() -> None:
    """The filter's mean propagation and the environment's truth integrate the same equations."""
    q0 = np.array([[0.9, 0.1, -0.3, 0.2]]) / np.linalg.norm([0.9, 0.1, -0.3, 0.2])
    w0 = np.array([[0.1, -0.25, 0.3]])
    q_true, w_true = FreeTumble(q0, w0, ASTROBEE_INERTIA, 0.1).advance(100)
    model = RigidBodyModel(inertia=ASTROBEE_INERTIA)
    x = np.zeros((1, 13))
    x[0, :4], x[0, 7:10], x[0, 10:13] = q0[0], w0[0], (0.01, 0.0, -0.02)
    for t in range(1, 100):
        x = model.predict(x, 0.1)
        x[0, :4] /= np.linalg.norm(x[0, :4])  # as the environment renormalises its samples
        np.testing.assert_allclose(x[0, :4], q_true[0, :, t], atol=1e-11)
        np.testing.assert_allclose(x[0, 7:10], w_true[0, :, t], atol=1e-11)
    np.testing.assert_allclose(x[0, 10:13], (0.01, 0.0, -0.02), rtol=0, atol=0)


def test_isotropic_body_keeps_its_world_rate_and_rotates_about_it() -> None:
    x = np.zeros((1, 13))
    x[0, :4], x[0, 7:10] = (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.5)
    exact = (np.cos(0.5), 0.0, 0.0, np.sin(0.5))  # 1 rad about z in 2 s
    for substeps, tolerance in ((1, 3e-4), (10, 3e-9)):  # RK4: the error of one step is O(h^5)
        out = RigidBodyModel(inertia=(2.0, 2.0, 2.0), substeps=substeps).predict(x, 2.0)
        np.testing.assert_allclose(out[0, 7:10], (0.0, 0.0, 0.5), atol=1e-15)
        np.testing.assert_allclose(out[0, :4], exact, atol=tolerance)


def test_rate_prediction_ignores_the_quaternion_norm() -> None:
    """The frame changes use q / |q|: a radial change of q (which the additive filter's
    covariance carries between updates) moves no rate."""
    model = RigidBodyModel(inertia=ASTROBEE_INERTIA)
    x = _states(model)
    _, F = model.transition(x, 0.1)
    radial = torch.zeros_like(x)
    radial[:, :4] = x[:, :4]
    torch.testing.assert_close((F @ radial[:, :, None])[:, 7:10, 0], torch.zeros(x.shape[0], 3, dtype=x.dtype), rtol=0, atol=1e-14)


def test_ratio_parametrisation() -> None:
    jx, jy, jz = ASTROBEE_INERTIA
    k = np.array([inertia_ratios(ASTROBEE_INERTIA)])
    np.testing.assert_allclose(moments_from_ratios(k)[0] * jz, ASTROBEE_INERTIA, rtol=1e-14)
    p = np.array(euler_coefficients(ASTROBEE_INERTIA))
    assert p.sum() + p.prod() == pytest.approx(0.0, abs=1e-16)  # Aghili & Parsa's constraint
    # the model with estimated ratios at the true ratios predicts what the known-inertia model does
    known, estimated = RigidBodyModel(inertia=ASTROBEE_INERTIA), RigidBodyModel(estimate_ratios=True)
    x = _states(known).numpy()
    augmented = np.concatenate((x, np.repeat(k, x.shape[0], axis=0)), axis=1)
    np.testing.assert_allclose(estimated.predict(augmented, 0.1)[:, :13], known.predict(x, 0.1), atol=1e-14)
    np.testing.assert_array_equal(estimated.predict(augmented, 0.1)[:, 13:], augmented[:, 13:])


def test_ratio_model_states_and_layout() -> None:
    model = RigidBodyModel(inertia=ASTROBEE_INERTIA, estimate_ratios=True)
    assert model.state_dim == 15 and len(model.layout.q_default) == 15 and len(model.layout.p0_default) == 15
    assert model.layout.q_labels[13:] == ("k1", "k2")
    z = np.array([[1.0, 0, 0, 0, 1, 2, 3]])
    x0 = model.initial_state(z)
    np.testing.assert_allclose(x0[0, 13:], inertia_ratios(ASTROBEE_INERTIA))
    np.testing.assert_array_equal(x0[0, :7], z[0])
    prior = model.prior_state(2, torch.float64)
    assert prior.shape == (2, 15) and float(prior[0, 0]) == 1.0
    assert RigidBodyModel(estimate_ratios=True).initial_state(z)[0, 13:].tolist() == [0.0, 0.0]  # isotropic prior


@pytest.mark.parametrize("variant", [ExtendedKalmanFilter, UnscentedKalmanFilter])
def test_filters_run_on_the_rigid_body_models(variant: type) -> None:
    from fkn_bench.envs import generate_episodes
    from fkn_bench.models import NoiseParameters

    episodes = generate_episodes("tumble-fast", 2, split="test")
    z, m = torch.from_numpy(episodes.measurements[:, :300]), torch.from_numpy(episodes.valid[:, :300])
    for model in (RigidBodyModel(inertia=ASTROBEE_INERTIA), RigidBodyModel(estimate_ratios=True)):
        layout = model.layout
        noise = NoiseParameters.from_std(layout.q_default, layout.r_default, layout.p0_default)
        result = variant(model=model).run(noise, z, m, dt=0.1)
        assert result.means.shape == (2, 300, model.state_dim)
        assert torch.isfinite(result.means).all() and torch.isfinite(result.covariances).all()
        torch.testing.assert_close(result.covariances, result.covariances.transpose(-1, -2), rtol=0, atol=0)
        assert bool((torch.linalg.eigvalsh(result.covariances[:, 100:]) > -1e-12).all())


def test_bad_options_are_refused_with_a_clear_message() -> None:
    with pytest.raises(ValueError, match="needs the principal moments"):
        RigidBodyModel()
    with pytest.raises(ValueError, match="inertia must be three finite positive"):
        RigidBodyModel(inertia=(1.0, -1.0, 1.0))
    with pytest.raises(ValueError, match="substeps"):
        RigidBodyModel(inertia=ASTROBEE_INERTIA, substeps=0)
    with pytest.raises(ValueError, match="unknown process model 'rigid'"):
        make_model("rigid")
    with pytest.raises(ValueError, match="takes no inertia"):
        make_model("constant-velocity", inertia=ASTROBEE_INERTIA)
    with pytest.raises(ValueError, match="pose-twist state"):
        MultiplicativeEKF(model=make_model("constant-velocity").__class__.__base__())  # a bare StateSpaceModel
    assert isinstance(make_model("constant-velocity"), PoseTwistModel)


def test_the_multiplicative_ekf_runs_any_pose_twist_model() -> None:
    """The MEKF maps a model's additive Jacobian to its error state; on an isotropic body (the
    constant rate) it stays close to the MEKF's exact constant-rate propagation."""
    from fkn_bench.envs import generate_episodes
    from fkn_bench.models import NoiseParameters

    episodes = generate_episodes("ds1", 2, split="test")
    z, m = torch.from_numpy(episodes.measurements[:, :400]), torch.from_numpy(episodes.valid[:, :400])
    exact = MultiplicativeEKF()
    layout = exact.layout
    noise = NoiseParameters.from_std(layout.q_default, layout.r_default, layout.p0_default)
    reference = exact.run(noise, z, m, dt=0.1).means
    isotropic = MultiplicativeEKF(model=RigidBodyModel(inertia=(1.0, 1.0, 1.0))).run(noise, z, m, dt=0.1).means
    assert float((isotropic - reference).abs().max()) < 2e-3
    ratios = MultiplicativeEKF(model=RigidBodyModel(estimate_ratios=True))
    assert ratios.covariance_dim == 14 and ratios.layout.q_labels[-2:] == ("k1", "k2")
    layout = ratios.layout
    result = ratios.run(NoiseParameters.from_std(layout.q_default, layout.r_default, layout.p0_default), z, m, dt=0.1)
    assert result.means.shape == (2, 400, 15) and bool(torch.isfinite(result.covariances).all())


def test_non_physical_ratios_are_evaluated_at_the_physical_boundary() -> None:
    """A physical body has |p_i| <= 1 (triangle inequality of its moments); log ratios outside
    that region give p clipped to [-1, 1], with zero derivative where clipped."""
    from fkn_bench.models.rigid_body import _coefficients_and_derivative

    physical = np.array([inertia_ratios(ASTROBEE_INERTIA), inertia_ratios((1.0, 1.0, 1.9))])
    p, dp = _coefficients_and_derivative(physical)
    np.testing.assert_allclose(p, [euler_coefficients(ASTROBEE_INERTIA), euler_coefficients((1.0, 1.0, 1.9))], atol=1e-15)
    assert np.abs(dp).max() > 0
    p, dp = _coefficients_and_derivative(np.array([[3.0, 3.0], [-4.0, 0.5]]))
    assert np.abs(p).max() == 1.0
    assert (dp[np.abs(p) == 1.0] == 0).all()


def test_fast_rows_are_integrated_finely_and_on_their_own() -> None:
    """30 rad/s over 0.1 s is outside one RK4 step's stability region (h |w| = 3): the row gets more
    steps and follows the exact rotation; a slow row in the same batch is integrated as alone."""
    model = RigidBodyModel(inertia=(2.0, 2.0, 2.0))
    x = np.zeros((2, 13))
    x[:, 0] = 1.0
    x[0, 7:10], x[1, 7:10] = (0.0, 0.0, 0.5), (0.0, 0.0, 30.0)
    out = model.predict(x, 0.1)
    np.testing.assert_allclose(out[1, :4], (np.cos(1.5), 0.0, 0.0, np.sin(1.5)), atol=1e-4)
    np.testing.assert_allclose(out[0], model.predict(x[:1], 0.1)[0], rtol=0, atol=1e-15)
    one_step = RigidBodyModel(inertia=(2.0, 2.0, 2.0))._rk4(x[1:, [0, 1, 2, 3, 7, 8, 9]], None, np.zeros((1, 3)), None, 0.1, 1)[0]
    assert np.abs(one_step[0, :4] - (np.cos(1.5), 0.0, 0.0, np.sin(1.5))).max() > 0.05  # what one step gives
    mean, F = model.transition(torch.from_numpy(x).requires_grad_(), 0.1)  # torch (differentiable) too
    torch.testing.assert_close(mean.detach(), torch.from_numpy(out), rtol=0, atol=1e-12)
