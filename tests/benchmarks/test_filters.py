"""Batched filter forward and forward + backward (EKF, UKF, MEKF; the EKF also at B = 1024, the
filter core's throughput target), the plain numpy reference, and the small-bmm limit at each
batch size (``fkn-bench bench report`` prints each batched filter's fraction of it)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
import torch

from fkn_bench.cli.bench import MATMULS_PER_STEP
from fkn_bench.filters import make_filter
from fkn_bench.gates.speed import (episodes_for, forward_backward_workload, manual_noise, numpy_ekf_loop, suite_device,
                                   suite_large_batch, synchronized)


BATCH, STEPS = 32, 400
DEVICE, LARGE_BATCH = suite_device(), suite_large_batch()


@pytest.fixture(scope="module")
def data() -> tuple[torch.Tensor, torch.Tensor, float]:
    z, m, dt = episodes_for("ds1", BATCH, STEPS)
    return torch.from_numpy(np.array(z)).to(DEVICE), torch.from_numpy(np.array(m)).to(DEVICE), dt


@pytest.mark.parametrize("variant", ["ekf", "ukf", "mekf"])
def test_filter_forward(benchmark: Any, data: Any, variant: str) -> None:
    z, m, dt = data
    noise = manual_noise(variant)
    filt = make_filter(variant)

    def run() -> Any:
        with torch.no_grad():
            return filt.run(noise, z, m, dt=dt)

    benchmark.pedantic(synchronized(run), rounds=5, warmup_rounds=1)
    benchmark.extra_info.update(steps=BATCH * STEPS, batch=BATCH, what=f"{variant} run(), {BATCH} x {STEPS}, no grad{ON}")


@pytest.mark.parametrize("variant", ["ekf", "ukf", "mekf"])
def test_filter_forward_backward(benchmark: Any, data: Any, variant: str) -> None:
    z, m, dt = data
    run = forward_backward_workload(make_filter(variant), manual_noise(variant), z, m, dt)
    benchmark.pedantic(synchronized(run), rounds=3, warmup_rounds=1)
    benchmark.extra_info.update(steps=BATCH * STEPS, batch=BATCH, what=f"{variant} run() + gradient of sigma_Q, {BATCH} x {STEPS}{ON}")


def test_numpy_reference_loop(benchmark: Any) -> None:
    """The speed gate's reference: the EKF in numpy, one sequence and one step at a time."""
    z, m, dt = episodes_for("ds1", BATCH, STEPS)
    noise = manual_noise("ekf")
    Q, R, P0 = (t.numpy() for t in (noise.process, noise.measurement, noise.initial))
    batch = 4
    benchmark.pedantic(lambda: numpy_ekf_loop(z[:batch], m[:batch], Q, R, P0, dt), rounds=5, warmup_rounds=1)
    benchmark.extra_info.update(steps=batch * STEPS, what=f"numpy EKF loop, {batch} x {STEPS}")


LARGE_STEPS = 200
ON = "" if DEVICE.type == "cpu" else f", on {DEVICE}"
EPISODES = 1024
"""Distinct episodes of the large batch; a larger batch (``FKN_BENCH_LARGE_BATCH``) repeats them:
the same work per row, without simulating 65536 whole episodes to keep 200 steps of each."""


@pytest.fixture(scope="module")
def large_data() -> tuple[torch.Tensor, torch.Tensor, float]:
    """ds1 (a measurement every 10 steps), test-split sequences of 200 steps, ``LARGE_BATCH`` of
    them (1024 distinct, repeated beyond)."""
    z, m, dt = episodes_for("ds1", min(LARGE_BATCH, EPISODES), LARGE_STEPS)
    repeats = -(-LARGE_BATCH // z.shape[0])
    z, m = (np.concatenate([a] * repeats)[:LARGE_BATCH] for a in (z, m))
    return torch.from_numpy(np.array(z)).to(DEVICE), torch.from_numpy(np.array(m)).to(DEVICE), dt


@pytest.mark.parametrize("outputs", ["means", "means+covariances"])
def test_ekf_forward_batch_1024(benchmark: Any, large_data: Any, outputs: str) -> None:
    """The filter core's throughput target (B = 1024, float64, one torch thread), with and
    without storing the per-step covariances and innovations."""
    z, m, dt = large_data
    noise = manual_noise("ekf")
    filt = make_filter("ekf")
    store = outputs != "means"

    def run() -> Any:
        with torch.no_grad():
            return filt.run(noise, z, m, dt=dt, store_covariances=store, store_innovations=store)

    benchmark.pedantic(synchronized(run), rounds=3, warmup_rounds=1)
    benchmark.extra_info.update(steps=LARGE_BATCH * LARGE_STEPS, batch=LARGE_BATCH,
                                what=f"ekf run(), {LARGE_BATCH} x {LARGE_STEPS}, {outputs}{ON}")


def test_ekf_forward_backward_batch_1024(benchmark: Any, large_data: Any) -> None:
    z, m, dt = large_data
    run = forward_backward_workload(make_filter("ekf"), manual_noise("ekf"), z, m, dt)
    benchmark.pedantic(synchronized(run), rounds=2, warmup_rounds=1)
    benchmark.extra_info.update(steps=LARGE_BATCH * LARGE_STEPS, batch=LARGE_BATCH,
                                what=f"ekf run() + gradient of sigma_Q, {LARGE_BATCH} x {LARGE_STEPS}{ON}")


@pytest.mark.parametrize("batch", [BATCH, LARGE_BATCH])
def test_small_bmm_limit(benchmark: Any, batch: int) -> None:
    """One ``torch.bmm`` of ``(B, 13, 13)`` float64 batches (one thread): ``steps`` per call is
    ``B / MATMULS_PER_STEP``, so the reported steps/s is the small-bmm limit at ``B``
    (:data:`fkn_bench.cli.bench.MATMULS_PER_STEP`)."""
    generator = torch.Generator().manual_seed(0)
    F, P = (torch.randn(batch, 13, 13, generator=generator, dtype=torch.float64).to(DEVICE) for _ in range(2))
    out = torch.empty_like(P)
    benchmark.pedantic(synchronized(lambda: torch.bmm(F, P, out=out)), rounds=7, iterations=max(1, 20480 // batch), warmup_rounds=1)
    benchmark.extra_info.update(steps=batch // MATMULS_PER_STEP, batch=batch, small_bmm_limit=True,
                                what=f"small-bmm limit: torch.bmm (B, 13, 13) float64, B = {batch}, {MATMULS_PER_STEP} per step{ON}")


@pytest.mark.parametrize("path", ["kernels", "torch-ops"])
@pytest.mark.parametrize("work", ["forward", "forward+backward"])
@pytest.mark.parametrize("batch", [64, LARGE_BATCH])
def test_ekf_step_paths(benchmark: Any, large_data: Any, monkeypatch: pytest.MonkeyPatch, batch: int, work: str, path: str) -> None:
    """The EKF of the paper's model with its step's compiled CPU kernels and with the torch
    operations that run where they do not (:mod:`fkn_bench.filters.kernels`), on the same
    inputs: their ratio is the kernels' gain at a training batch (64) and at B = 1024."""
    from fkn_bench.filters import ekf, kernels

    if path == "kernels" and DEVICE.type != "cpu":
        pytest.skip("the compiled kernels are the CPU's")
    monkeypatch.setattr(kernels, "ENABLED", path == "kernels")
    monkeypatch.setattr(ekf, "STRUCTURED_MIN_BATCH", 1)  # torch-ops: the structured step, as on a GPU
    z, m, dt = large_data
    z, m = z[:batch], m[:batch]
    filt = make_filter("ekf")
    if work == "forward":
        def run() -> Any:
            with torch.no_grad():
                return filt.run(manual_noise("ekf"), z, m, dt=dt, store_covariances=False, store_innovations=False)
    else:
        run = forward_backward_workload(filt, manual_noise("ekf"), z, m, dt)
    benchmark.pedantic(synchronized(run), rounds=3, warmup_rounds=1)
    benchmark.extra_info.update(steps=batch * LARGE_STEPS, batch=batch,
                                what=f"ekf run(), {batch} x {LARGE_STEPS}, {work}, {path}{ON}")
