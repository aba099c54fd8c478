"""Long-run stability: 3e4 steps of ds1-flips (3000 measurements, half of them sign-flipped, 1%
gross outliers: the filters reach their steady state within about 100 updates, so this is thirty
times that) through every baseline, batched estimate(): no NaN, and every 12x12 error covariance
positive definite. (1e5 steps until 2026-11-27: 48 s of the test command's 292 s, for the same
verdicts.)

The EKF-family estimators (manual-ekf, nll-tuned-ekf, direct-tuned-ekf) differ only in their
constant noise parameters, so one batched EKF run carries all three parameter sets side by side
(one sequence each): the same recursion and checks at the cost of one run."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fkn_bench.envs import generate_episodes
from fkn_bench.estimators import make_estimator
from fkn_bench.filters import ExtendedKalmanFilter
from fkn_bench.models import NoiseParameters
from fkn_bench.filters.pose import error_covariance_from_state
from fkn_bench.scenarios import get_scenario

BASELINES = ("sage-husa", "akhlaghi", "vbakf")
EKF_PARAMETER_SETS = ("manual-ekf", "nll-tuned-ekf", "direct-tuned-ekf")
STEPS = 30_000


@pytest.fixture(scope="module")
def long_flips():  # noqa: ANN201
    scenario = get_scenario("ds1-flips", n_steps=STEPS)
    return scenario, generate_episodes(scenario, [7])


@pytest.mark.slow(seconds=12)  # the file: four runs of 3e4 steps
@pytest.mark.parametrize("name", BASELINES)
def test_no_nan_and_positive_definite_covariances_over_3e4_steps(name: str, long_flips) -> None:
    scenario, episodes = long_flips
    assert episodes.n_steps == STEPS and (episodes.measurements[episodes.valid][:, 0] < 0).any()
    result = make_estimator(name, scenario=scenario).estimate(episodes.measurements, episodes.valid, scenario.dt)
    for array in (result.means, result.covariances, result.innovations, result.innovation_covariances):
        assert np.isfinite(array).all()
    error_covariances = result.error_covariances[0]
    assert np.isfinite(error_covariances).all()
    for start in range(0, STEPS, 10_000):  # in chunks: eigvalsh of many 12x12 matrices at once is large
        assert np.linalg.eigvalsh(error_covariances[start : start + 10_000]).min() > 0
    # the estimate keeps tracking over the last 1000 steps, except Akhlaghi's (documented in
    # fkn_bench.baselines.akhlaghi: outliers inflate its residual-based R, and the sluggish
    # filter's own error then keeps R inflated: it drifts for long stretches, metres and tens of
    # degrees off, though finite and positive definite)
    final = slice(STEPS - 1000, STEPS)
    position_error = np.linalg.norm(result.means[0, final, 4:7] - episodes.truth[0, final, 4:7], axis=-1)
    if name != "akhlaghi":
        assert np.sqrt((position_error**2).mean()) < 0.2


@pytest.mark.slow
def test_ekf_with_manual_and_tuned_parameters_stays_finite_and_positive_definite_over_3e4_steps(long_flips) -> None:
    """The batched EKF with each EKF estimator's parameters (a batch of three copies of the
    sequence): sign flips at half the measurements, 1% gross outliers, a measurement every 10
    steps; no NaN, the 13x13 covariance exactly symmetric, the 12-dim error covariance symmetric
    positive definite throughout, and the estimate still tracking at the end."""
    scenario, episodes = long_flips
    assert episodes.valid.sum() == STEPS // 10
    noises = [make_estimator(name, scenario=scenario).noise_parameters() for name in EKF_PARAMETER_SETS]
    noise = NoiseParameters(*(torch.stack([getattr(n, f) for n in noises]) for f in ("process", "measurement", "initial")))
    batch = len(EKF_PARAMETER_SETS)
    variant = ExtendedKalmanFilter()
    with torch.no_grad():  # (no gradients needed: saves the autograd bookkeeping)
        result = variant.run(
            noise,
            torch.from_numpy(np.repeat(episodes.measurements, batch, axis=0)),
            torch.from_numpy(np.repeat(episodes.valid, batch, axis=0)),
            dt=scenario.dt,
            store_innovations=False,
        )
    for b, name in enumerate(EKF_PARAMETER_SETS):
        means, covariances = result.means[b].numpy(), result.covariances[b].numpy()
        updated = result.updated[b].numpy()
        assert updated.sum() > 0.99 * STEPS // 10, name  # nearly every measurement went in (outliers included)
        assert np.isfinite(means).all(), name
        smallest = np.inf
        for start in range(0, STEPS, 10_000):  # in chunks: the checks' temporaries stay small
            chunk = slice(start, start + 10_000)
            P = covariances[chunk]
            assert np.isfinite(P).all(), name
            # exact: the filter symmetrises P after every update as (P + P^T) / 2, whose (i, j)
            # and (j, i) entries are the same IEEE sum of the same two numbers
            np.testing.assert_array_equal(P[updated[chunk]], np.swapaxes(P[updated[chunk]], -1, -2), err_msg=name)
            # predict-only steps: F P F^T + Q in float64, rounding of a 13-term dot product
            np.testing.assert_allclose(P, np.swapaxes(P, -1, -2), rtol=0, atol=1e-15, err_msg=name)
            error = error_covariance_from_state(means[chunk, :4], P)
            np.testing.assert_allclose(error, np.swapaxes(error, -1, -2), rtol=0, atol=1e-15, err_msg=name)
            smallest = min(smallest, np.linalg.eigvalsh(error).min())
        assert smallest > 0, name
        final = slice(STEPS - 1000, STEPS)
        position_error = np.linalg.norm(means[final, 4:7] - episodes.truth[0, final, 4:7], axis=-1)
        assert np.sqrt((position_error**2).mean()) < 0.2, name
