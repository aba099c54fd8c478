"""KalmanFilter.run: its conventions, the interchangeable variants, gradients, dtypes,
time-varying noise, adversarial inputs and input validation."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from fkn_bench.envs import generate_episodes
from fkn_bench.filters import (
    VARIANTS,
    ExtendedKalmanFilter,
    FilterState,
    KalmanFilter,
    MultiplicativeEKF,
    ParameterSet,
    UnscentedKalmanFilter,
    make_filter,
)
from fkn_bench.geometry.quaternion import angle_between
from fkn_bench.models import NoiseParameters

ALL_VARIANTS = ("ekf", "ukf", "mekf")


@pytest.fixture(scope="module")
def ds1_short() -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Two ds1 training windows of 300 steps (a measurement every 10 steps)."""
    episodes = generate_episodes("ds1", [0, 1], split="train").window(0, 300)
    return (
        torch.from_numpy(episodes.measurements),
        torch.from_numpy(episodes.valid),
        torch.from_numpy(episodes.truth),
    )


def _with_sign_flips(z: torch.Tensor, seed: int) -> torch.Tensor:
    flips = torch.from_numpy(np.random.default_rng(seed).random(z.shape[:2]) < 0.5)
    out = z.clone()
    out[..., :4] = torch.where(flips[..., None], -z[..., :4], z[..., :4])
    return out


# ---------------------------------------------------------------------------- registry of variants
def test_variants_and_make_filter() -> None:
    assert set(VARIANTS) == set(ALL_VARIANTS)
    assert isinstance(make_filter("ekf"), ExtendedKalmanFilter)
    assert isinstance(make_filter("ukf", alpha=0.5), UnscentedKalmanFilter)
    assert isinstance(make_filter("mekf"), MultiplicativeEKF)
    with pytest.raises(ValueError, match="unknown filter variant 'kf'; valid variants: ekf, ukf, mekf"):
        make_filter("kf")


@pytest.mark.parametrize("name", ALL_VARIANTS)
def test_identical_call_runs_every_variant(name: str, ds1_short) -> None:
    z, mask, truth = ds1_short
    variant = make_filter(name)
    result = variant.run(variant.layout.default_noise(), z, mask, dt=0.1)
    k, m = variant.covariance_dim, variant.innovation_dim
    B, T = mask.shape
    assert result.means.shape == (B, T, 13) and result.means.dtype == torch.float64
    assert result.covariances is not None and result.covariances.shape == (B, T, k, k)
    assert result.innovations is not None and result.innovations.shape == (B, T, m)
    assert result.innovation_covariances is not None and result.innovation_covariances.shape == (B, T, m, m)
    assert torch.isfinite(result.means).all() and torch.isfinite(result.covariances).all()
    # first measurement initialises, every later one updates
    first = int(mask[0].nonzero()[0])
    assert result.updated.sum() == mask.sum() - B
    assert not result.updated[0, first] and result.initialised[0, first] and not result.initialised[0, :first].any()
    # unit quaternions after every update (the additive predictions drift off the sphere)
    norms = result.means[..., :4].norm(dim=-1)
    torch.testing.assert_close(norms[result.updated], torch.ones(int(result.updated.sum()), dtype=torch.float64))
    if name == "mekf":  # the multiplicative prediction stays on it
        torch.testing.assert_close(norms[:, first:], torch.ones(B, T - first, dtype=torch.float64))
    assert isinstance(result.final, FilterState)
    # exact: the last stored mean is the final state itself (a copy, no arithmetic)
    torch.testing.assert_close(result.final.mean, result.means[:, -1], rtol=0, atol=0)


def test_variants_give_close_results_on_ds1(ds1_short) -> None:
    z, mask, truth = ds1_short
    means = {}
    for name in ALL_VARIANTS:
        variant = make_filter(name)
        means[name] = variant.run(variant.layout.default_noise(), z, mask, dt=0.1).means.numpy()
    settled = slice(100, None)
    for name in ("ukf", "mekf"):
        angle = angle_between(means["ekf"][:, settled, :4], means[name][:, settled, :4])
        assert angle.max() < 0.02, name  # rad, against an attitude error of ~0.1 rad
        np.testing.assert_allclose(means[name][:, settled, 4:], means["ekf"][:, settled, 4:], rtol=0, atol=5e-3)
    # and all are far closer to each other than to the truth
    error = angle_between(means["ekf"][:, settled, :4], truth[:, settled, :4].numpy())
    assert np.sqrt(np.mean(error**2)) > 0.03


# ---------------------------------------------------------------------------- conventions of run()
def test_initialisation_at_first_usable_measurement() -> None:
    variant = make_filter("ekf")
    noise = variant.layout.default_noise()
    z = torch.full((2, 6, 7), float("nan"), dtype=torch.float64)
    mask = torch.zeros(2, 6, dtype=torch.bool)
    z[0, 2] = torch.tensor([0.0, 2.0, 0.0, 0.0, 1.0, 2.0, 3.0])  # non-unit: renormalised
    mask[0, 2] = True
    mask[0, 1] = True  # NaN inside the mask: skipped, no initialisation there
    result = variant.run(noise, z, mask, dt=0.1)
    # row 0: prior (identity attitude, zeros) before step 2, then the measurement with rates zero
    prior = torch.zeros(13, dtype=torch.float64)
    prior[0] = 1.0
    # exact (this test): the prior and its prediction at zero rate involve only products with 0 and
    # 1 and sums with 0, and the initial state and covariance are copies of z and noise.initial
    torch.testing.assert_close(result.means[0, :2], prior.expand(2, 13), rtol=0, atol=0)
    torch.testing.assert_close(result.means[0, 2, :7], torch.tensor([0.0, 1.0, 0, 0, 1, 2, 3], dtype=torch.float64))
    assert (result.means[0, 2, 7:] == 0).all()
    torch.testing.assert_close(result.covariances[0, 2], noise.initial, rtol=0, atol=0)
    assert result.initialised[0].tolist() == [False, False, True, True, True, True]
    assert not result.updated.any()
    # row 1 never sees a measurement: the prior throughout
    assert not result.initialised[1].any()
    torch.testing.assert_close(result.means[1], prior.expand(6, 13), rtol=0, atol=0)


@pytest.mark.parametrize("name", ALL_VARIANTS)
def test_missing_steps_are_predict_only(name: str, ds1_short) -> None:
    z, mask, _ = ds1_short
    variant = make_filter(name)
    noise = variant.layout.default_noise()
    result = variant.run(noise, z[:1, :60], mask[:1, :60], dt=0.1)
    for t in range(1, 60):
        if mask[0, t]:
            continue
        previous = FilterState(result.means[:, t - 1], result.covariances[:, t - 1])
        predicted = variant.predict(previous, noise.process, 0.1)
        # exact: run() stored this very predict() of the same (1, ...) operands, in this process
        torch.testing.assert_close(result.means[:, t], predicted.mean, rtol=0, atol=0)
        torch.testing.assert_close(result.covariances[:, t], predicted.covariance, rtol=0, atol=0)
        assert not result.updated[0, t]
        assert (result.innovations[0, t] == 0).all()
        torch.testing.assert_close(result.innovation_covariances[0, t], torch.eye(variant.innovation_dim, dtype=torch.float64))


class _StepByStepEKF(ExtendedKalmanFilter):
    """The EKF with the base class's ``predict_steps``: one ``predict`` per step."""

    def predict_steps(self, *args, **kwargs):  # type: ignore[no-untyped-def]
        return KalmanFilter.predict_steps(self, *args, **kwargs)


@pytest.mark.parametrize("time_varying", [False, True])
def test_stretches_without_measurements_are_predicted_in_one_call_as_step_by_step(time_varying: bool, ds1_short) -> None:
    """run() predicts a stretch of steps without a measurement, and the step after it, in one
    ``predict_steps`` call (the EKF's compiled kernels): the same states, bit for bit, as one
    ``predict`` per step, and the same gradients to rounding, with a stretch at the end of the
    sequences, an initialisation in the middle, per-step ``Q`` and every output stored."""
    z, mask, _ = ds1_short
    z, mask = z[:, :95].clone(), mask[:, :95].clone()
    mask[1, :43] = False  # sequence 1 initialises at step 50
    mask[:, 85:] = False  # a stretch ends the sequences
    B, T = mask.shape
    outputs = []
    for variant in (ExtendedKalmanFilter(), _StepByStepEKF()):
        g = torch.Generator().manual_seed(0)
        shape = (B, T, 13) if time_varying else (13,)
        q_std = (0.01 + 0.01 * torch.rand(shape, generator=g, dtype=torch.float64)).requires_grad_(True)
        r_std = torch.full((7,), 0.02, dtype=torch.float64, requires_grad=True)
        p0_std = torch.full((13,), 0.3, dtype=torch.float64, requires_grad=True)
        result = variant.run(NoiseParameters.from_std(q_std, r_std, p0_std), z, mask, dt=0.1)
        loss = result.means.square().sum() + result.covariances.sum() + result.innovations.square().sum()
        loss = loss + result.prior_means.sum() + result.innovation_covariances.sum()
        outputs.append([result.means, result.covariances, result.innovations, result.prior_means,
                        *torch.autograd.grad(loss, (q_std, r_std, p0_std))])
    for name, a, b in zip(("means", "covariances", "innovations", "prior means"), outputs[0][:4], outputs[1][:4]):
        assert torch.equal(a, b), name
    for name, a, b in zip(("dQ", "dR", "dP0"), outputs[0][4:], outputs[1][4:]):
        torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-15, msg=name)


@pytest.mark.parametrize("name", ALL_VARIANTS)
def test_continuing_from_final_state_equals_one_run(name: str, ds1_short) -> None:
    z, mask, _ = ds1_short
    variant = make_filter(name)
    noise = variant.layout.default_noise()
    whole = variant.run(noise, z, mask, dt=0.1)
    first = variant.run(noise, z[:, :137], mask[:, :137], dt=0.1)
    # run() does not predict at t = 0 of the continuation: predict once by hand
    start = variant.predict(first.final, noise.process, 0.1)
    second = variant.run(noise, z[:, 137:], mask[:, 137:], dt=0.1, initial=start)
    torch.testing.assert_close(second.means, whole.means[:, 137:], rtol=0, atol=1e-13)
    torch.testing.assert_close(second.covariances, whole.covariances[:, 137:], rtol=0, atol=1e-13)


def test_store_flags_and_batch_independence(ds1_short) -> None:
    z, mask, _ = ds1_short
    variant = make_filter("ekf")
    noise = variant.layout.default_noise()
    full = variant.run(noise, z, mask, dt=0.1)
    lean = variant.run(noise, z, mask, dt=0.1, store_covariances=False, store_innovations=False)
    assert lean.covariances is None and lean.innovations is None
    assert lean.innovation_covariances is None and lean.prior_means is None
    # exact: the store flags change what is kept, not the arithmetic (same computation twice)
    torch.testing.assert_close(lean.means, full.means, rtol=0, atol=0)
    # (the last steps predict without a measurement: the final state of a stretch kept without its series)
    torch.testing.assert_close(lean.final.covariance, full.final.covariance, rtol=0, atol=0)
    torch.testing.assert_close(lean.final.mean, full.final.mean, rtol=0, atol=0)
    for b in range(z.shape[0]):
        alone = variant.run(noise, z[b : b + 1], mask[b : b + 1], dt=0.1)
        torch.testing.assert_close(alone.means[0], full.means[b], rtol=0, atol=1e-13)
        torch.testing.assert_close(alone.covariances[0], full.covariances[b], rtol=0, atol=1e-13)


def test_innovations_and_prior_means(ds1_short) -> None:
    z, mask, _ = ds1_short
    variant = make_filter("ekf")
    noise = variant.layout.default_noise()
    result = variant.run(noise, z[:1], mask[:1], dt=0.1)
    for t in result.updated[0].nonzero()[:, 0].tolist()[:5]:
        prior = result.prior_means[0, t]
        measured = z[0, t].clone()
        measured[:4] /= measured[:4].norm()
        if float(measured[:4] @ prior[:4]) < 0:
            measured[:4] = -measured[:4]
        torch.testing.assert_close(result.innovations[0, t], measured - prior[:7], rtol=0, atol=1e-15)
        P_prior = variant.predict(FilterState(result.means[:, t - 1], result.covariances[:, t - 1]), noise.process, 0.1).covariance
        torch.testing.assert_close(result.innovation_covariances[0, t], P_prior[0, :7, :7] + noise.measurement, rtol=0, atol=1e-15)


# ---------------------------------------------------------------------------- gradients and dtypes
@pytest.mark.parametrize("name", ALL_VARIANTS)
@pytest.mark.parametrize(
    ("learn", "positivity"), [(("q_std", "r_std"), "log"), (("q_chol", "r_chol", "p0_std"), "softplus")]
)
def test_gradients_reach_every_learnable_parameter(name: str, learn: tuple[str, ...], positivity: str, ds1_short) -> None:
    z, mask, truth = ds1_short
    z, mask, truth = z[:, :120], mask[:, :120], truth[:, :120]
    variant = make_filter(name)
    parameters = ParameterSet(variant.layout, learn=learn, positivity=positivity)  # type: ignore[arg-type]
    raw = parameters.initial_values().requires_grad_(True)
    result = variant.run(parameters.to_noise(raw), z, mask, dt=0.1, store_covariances=False)
    loss = ((result.means[:, 20:] - truth[:, 20:]) ** 2).mean()
    loss.backward()
    assert raw.grad is not None and torch.isfinite(raw.grad).all()
    dead = [n for n, g in zip(parameters.names(), raw.grad.tolist()) if g == 0.0]
    assert not dead, f"no gradient reaches {dead}"


def test_gradients_flow_through_nan_measurements(ds1_short) -> None:
    """NaN outside the mask (missing) and inside it (skipped) must not poison the backward pass."""
    z, mask, truth = ds1_short
    z, mask, truth = z[:1, :80].clone(), mask[:1, :80].clone(), truth[:1, :80]
    mask[0, 35] = True  # NaN inside the mask
    assert torch.isnan(z[0, 35]).all()
    variant = make_filter("ekf")
    parameters = ParameterSet(variant.layout)
    raw = parameters.initial_values().requires_grad_(True)
    result = variant.run(parameters.to_noise(raw), z, mask, dt=0.1)
    ((result.means - truth) ** 2).mean().backward()
    assert torch.isfinite(raw.grad).all() and (raw.grad != 0).any()


@pytest.mark.parametrize("name", ALL_VARIANTS)
def test_float32_follows_the_measurements(name: str, ds1_short) -> None:
    z, mask, _ = ds1_short
    variant = make_filter(name)
    noise = variant.layout.default_noise()  # float64: converted to the measurements' dtype
    r32 = variant.run(noise, z.float(), mask, dt=0.1)
    r64 = variant.run(noise, z, mask, dt=0.1)
    assert r32.means.dtype == torch.float32 and r32.covariances.dtype == torch.float32
    assert r32.final.mean.dtype == torch.float32
    assert torch.isfinite(r32.means).all() and torch.isfinite(r32.covariances).all()
    angle = angle_between(r32.means[..., :4].double().numpy(), r64.means[..., :4].numpy())
    assert angle.max() < 1e-4
    torch.testing.assert_close(r32.means[..., 4:].double(), r64.means[..., 4:], rtol=0, atol=2e-4)


# ---------------------------------------------------------------------------- time-varying noise
def test_time_varying_measurement_noise_is_used_per_step(ds1_short) -> None:
    z, mask, _ = ds1_short
    z, mask = z[:, :200], mask[:, :200]
    variant = make_filter("ekf")
    base = variant.layout.default_noise()
    B, T = mask.shape
    constant = variant.run(base, z, mask, dt=0.1)

    def per_step(R: torch.Tensor) -> NoiseParameters:
        return NoiseParameters(base.process, R, base.initial)

    # the same R at every step: identical to the constant parameters
    R = base.measurement.expand(B, T, 7, 7).clone()
    same = variant.run(per_step(R), z, mask, dt=0.1)
    # not exact: the per-step R is a (B, 7, 7) view with a real batch stride, the constant one an
    # expanded (stride-0) matrix, and BLAS may take a different batched-product kernel for each
    # (bit-identical on the machines tried); atol=1e-13 as for the batch-independence check above
    torch.testing.assert_close(same.means, constant.means, rtol=0, atol=1e-13)
    # a larger R from step 100 on: identical before, different after, and a smaller gain
    R[:, 100:] *= 25.0
    changed = variant.run(per_step(R), z, mask, dt=0.1)
    torch.testing.assert_close(changed.means[:, :100], constant.means[:, :100], rtol=0, atol=1e-13)  # (as above)
    assert (changed.means[:, 100:] - constant.means[:, 100:]).abs().amax() > 1e-3
    step = int(mask[0, 100:].nonzero()[0]) + 100
    gain = lambda r: (r.means[0, step, 4:7] - r.prior_means[0, step, 4:7]).norm()  # noqa: E731
    assert gain(changed) < 0.5 * gain(constant)
    torch.testing.assert_close(changed.innovation_covariances[0, step] - constant.innovation_covariances[0, step],
                               24.0 * base.measurement, rtol=0, atol=1e-12)
    # an enormous R at one measurement step: as if that measurement were missing, for the
    # position and velocity (the attitude differs by the renormalisation and projection that an
    # update applies even with a vanishing gain)
    R = base.measurement.expand(B, T, 7, 7).clone()
    R[:, step] *= 1e16
    ignored = variant.run(per_step(R), z, mask, dt=0.1)
    skipped_mask = mask.clone()
    skipped_mask[:, step] = False
    skipped = variant.run(base, z, skipped_mask, dt=0.1)
    for part in (slice(4, 7), slice(10, 13)):
        torch.testing.assert_close(ignored.means[..., part], skipped.means[..., part], rtol=0, atol=1e-12)
    assert angle_between(ignored.means[..., :4].numpy(), skipped.means[..., :4].numpy()).max() < 1e-3


def test_time_varying_process_noise_and_per_sequence_noise(ds1_short) -> None:
    z, mask, _ = ds1_short
    z, mask = z[:, :100], mask[:, :100]
    variant = make_filter("ekf")
    base = variant.layout.default_noise()
    B, T = mask.shape
    Q = base.process.expand(B, T, 13, 13).clone()
    Q[1] *= 4.0  # sequence 1 only
    result = variant.run(NoiseParameters(Q, base.measurement, base.initial), z, mask, dt=0.1)
    per_sequence = variant.run(NoiseParameters(Q[:, 0], base.measurement, base.initial), z, mask, dt=0.1)
    reference = variant.run(base, z, mask, dt=0.1)
    # exact: Q[:, t] and Q[:, 0] are equal-valued views with the same strides, used only as the
    # added term of F P F^T + Q: the same kernels on the same operands
    torch.testing.assert_close(result.means, per_sequence.means, rtol=0, atol=0)
    torch.testing.assert_close(result.means[0], reference.means[0], rtol=0, atol=1e-15)
    assert (result.means[1] - reference.means[1]).abs().amax() > 1e-3


# ---------------------------------------------------------------------------- adversarial inputs
@pytest.mark.parametrize("name", ALL_VARIANTS)
def test_adversarial_measurements(name: str, ds1_short) -> None:
    z, mask, _ = ds1_short
    z, mask = z[:1, :150].clone(), mask[:1, :150].clone()
    variant = make_filter(name)
    noise = variant.layout.default_noise()
    clean = variant.run(noise, z, mask, dt=0.1)
    steps = mask[0].nonzero()[:, 0].tolist()

    # garbage outside the mask is ignored
    garbage = z.clone()
    garbage[~mask] = torch.tensor([float("nan"), float("inf"), -float("inf"), 1e300, 0.0, 5.0, float("nan")], dtype=torch.float64)
    # exact here and below: sanitize() zeroes the dropped entries, so the arithmetic is the same
    torch.testing.assert_close(variant.run(noise, garbage, mask, dt=0.1).means, clean.means, rtol=0, atol=0)

    # NaN, inf or a zero quaternion inside the mask: that update is skipped
    bad = z.clone()
    bad[0, steps[3], 2] = float("nan")
    bad[0, steps[5], 5] = float("inf")
    bad[0, steps[7], :4] = 0.0
    skipped_mask = mask.clone()
    skipped_mask[0, [steps[3], steps[5], steps[7]]] = False
    result = variant.run(noise, bad, mask, dt=0.1)
    torch.testing.assert_close(result.means, variant.run(noise, z, skipped_mask, dt=0.1).means, rtol=0, atol=0)
    assert not result.updated[0, [steps[3], steps[5], steps[7]]].any()
    assert torch.isfinite(result.means).all() and torch.isfinite(result.covariances).all()

    # non-unit quaternions are renormalised
    scaled = z.clone()
    scaled[..., :4] *= torch.from_numpy(np.random.default_rng(0).uniform(0.01, 100.0, (1, z.shape[1], 1)))
    torch.testing.assert_close(variant.run(noise, scaled, mask, dt=0.1).means, clean.means, rtol=0, atol=1e-12)

    # a sign flip at every step changes nothing but (possibly) the estimate's own sign
    flipped = z.clone()
    flipped[..., :4] *= -1.0
    # (exactly for the EKF and MEKF on any IEEE machine: round-to-nearest is sign-symmetric, so
    # negating the quaternion negates every intermediate that depends on it, bit for bit; the UKF's
    # weighted sums of negated sigma points round differently, ~1e-14)
    result = variant.run(noise, flipped, mask, dt=0.1)
    atol = 1e-12 if name == "ukf" else 0.0
    torch.testing.assert_close(result.means[..., 4:], clean.means[..., 4:], rtol=0, atol=atol)
    torch.testing.assert_close(result.means[..., :4].abs(), clean.means[..., :4].abs(), rtol=0, atol=atol)

    # gross outliers: finite output
    outliers = z.clone()
    outliers[0, steps[4], 4:7] = 1e6
    outliers[0, steps[6], :4] = torch.tensor([1e6, -1e6, 3.0, 0.0], dtype=torch.float64)
    outliers[0, steps[8]] = -1e6
    outliers[0, steps[9], :4] = 1e160  # |q|^2 overflows: skipped
    result = variant.run(noise, outliers, mask, dt=0.1)
    assert torch.isfinite(result.means).all() and torch.isfinite(result.covariances).all()
    assert torch.isfinite(result.innovations).all() and torch.isfinite(result.innovation_covariances).all()
    assert result.means[0, steps[4], 4:7].abs().max() > 1e4  # the outlier did go in


@pytest.mark.parametrize("name", ALL_VARIANTS)
def test_input_validation(name: str) -> None:
    variant = make_filter(name)
    noise = variant.layout.default_noise()
    z = torch.zeros(2, 5, 7, dtype=torch.float64)
    z[..., 0] = 1.0
    mask = torch.ones(2, 5, dtype=torch.bool)
    with pytest.raises(ValueError, match=r"measurements must have shape \(B, T, 7\) \(got \(5, 7\)\)"):
        variant.run(noise, z[0], mask[0], dt=0.1)
    with pytest.raises(ValueError, match=r"measurements must have shape \(B, T, 7\) \(got \(2, 5, 6\)\)"):
        variant.run(noise, z[..., :6], mask, dt=0.1)
    with pytest.raises(ValueError, match=r"mask must have shape \(2, 5\) \(got \(2, 4\)\)"):
        variant.run(noise, z, mask[:, :4], dt=0.1)
    with pytest.raises(ValueError, match="no sequences or no time steps"):
        variant.run(noise, z[:, :0], mask[:, :0], dt=0.1)
    with pytest.raises(ValueError, match="no sequences or no time steps"):
        variant.run(noise, z[:0], mask[:0], dt=0.1)
    with pytest.raises(ValueError, match="floating point"):
        variant.run(noise, z.long(), mask, dt=0.1)
    for dt in (0.0, -0.1, math.nan, math.inf, "fast", None, True, "0.1", 10**400):  # no bool, no string, nothing beyond float
        with pytest.raises(ValueError, match="dt must be"):
            variant.run(noise, z, mask, dt=dt)  # type: ignore[arg-type]
    k, m = variant.covariance_dim, variant.innovation_dim
    wrong = [
        NoiseParameters(noise.process, noise.measurement[:-1, :-1], noise.initial),
        NoiseParameters(noise.process.expand(3, k, k), noise.measurement, noise.initial),
        NoiseParameters(noise.process.expand(2, 4, k, k), noise.measurement, noise.initial),
        NoiseParameters(noise.process, noise.measurement, torch.eye(k + 1, dtype=torch.float64)),
    ]
    for bad in wrong:
        with pytest.raises(ValueError, match=r"noise\.(process|measurement|initial) must have shape"):
            variant.run(bad, z, mask, dt=0.1)
    # accepted leading axes: (), (1,), (B,), (B, T)
    for Q in (noise.process, noise.process[None], noise.process.expand(2, k, k), noise.process.expand(2, 5, k, k)):
        assert torch.isfinite(variant.run(NoiseParameters(Q, noise.measurement, noise.initial), z, mask, dt=0.1).means).all()
    assert m == (6 if name == "mekf" else 7)
