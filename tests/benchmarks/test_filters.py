"""Batched filter forward and forward + backward (EKF, UKF, MEKF), and the plain numpy reference."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
import torch

from fkn_bench.filters import NoiseParameters, make_filter
from fkn_bench.gates.speed import episodes_for, manual_noise, numpy_ekf_loop


BATCH, STEPS = 32, 400


@pytest.fixture(scope="module")
def data() -> tuple[torch.Tensor, torch.Tensor, float]:
    z, m, dt = episodes_for("ds1", BATCH, STEPS)
    return torch.from_numpy(np.array(z)), torch.from_numpy(np.array(m)), dt


@pytest.mark.parametrize("variant", ["ekf", "ukf", "mekf"])
def test_filter_forward(benchmark: Any, data: Any, variant: str) -> None:
    z, m, dt = data
    noise = manual_noise(variant)
    filt = make_filter(variant)

    def run() -> Any:
        with torch.no_grad():
            return filt.run(noise, z, m, dt=dt)

    benchmark.pedantic(run, rounds=5, warmup_rounds=1)
    benchmark.extra_info.update(steps=BATCH * STEPS, what=f"{variant} run(), {BATCH} x {STEPS}, no grad")


@pytest.mark.parametrize("variant", ["ekf", "ukf", "mekf"])
def test_filter_forward_backward(benchmark: Any, data: Any, variant: str) -> None:
    z, m, dt = data
    noise = manual_noise(variant)
    filt = make_filter(variant)
    log_std = torch.log(torch.diagonal(noise.process)).mul(0.5).clone().requires_grad_(True)

    def run() -> Any:
        process = torch.diag_embed(torch.exp(2.0 * log_std))
        result = filt.run(NoiseParameters(process, noise.measurement, noise.initial), z, m, dt=dt,
                          store_covariances=False, store_innovations=False)
        return torch.autograd.grad(result.means.square().mean(), log_std)

    benchmark.pedantic(run, rounds=3, warmup_rounds=1)
    benchmark.extra_info.update(steps=BATCH * STEPS, what=f"{variant} run() + gradient of sigma_Q, {BATCH} x {STEPS}")


def test_numpy_reference_loop(benchmark: Any) -> None:
    """The speed gate's reference: the EKF in numpy, one sequence and one step at a time."""
    z, m, dt = episodes_for("ds1", BATCH, STEPS)
    noise = manual_noise("ekf")
    Q, R, P0 = (t.numpy() for t in (noise.process, noise.measurement, noise.initial))
    batch = 4
    benchmark.pedantic(lambda: numpy_ekf_loop(z[:batch], m[:batch], Q, R, P0, dt), rounds=5, warmup_rounds=1)
    benchmark.extra_info.update(steps=batch * STEPS, what=f"numpy EKF loop, {batch} x {STEPS}")
