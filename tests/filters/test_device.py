"""The batched filters run where their inputs are (``--device cuda`` where a GPU exists).

A machine without a GPU cannot run CUDA, but it can catch what would break there: a tensor made
without ``device=``, which lands on the default device instead of the inputs'. These tests make
the default device ``meta`` (shapes, no data) while the inputs stay on the CPU, so every such
tensor meets a CPU tensor and the operation raises "Tensor on device meta is not on the expected
device cpu" (stricter than CUDA, which lets 0-d CPU tensors mix in). The torch-operations path is
forced, as on a GPU, where the compiled CPU kernels (:mod:`fkn_bench.filters.kernels`) never run.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager

import numpy as np
import pytest
import torch

from fkn_bench.filters import VARIANTS, FilterState, make_filter
from fkn_bench.models import NoiseParameters, make_model, model_names


@pytest.fixture
def on_meta(meta_default_device: Callable[[], AbstractContextManager[None]]) -> Iterator[None]:
    with meta_default_device():
        yield


def _episodes(batch: int = 4, steps: int = 40) -> tuple[torch.Tensor, torch.Tensor]:
    """Noisy poses of a slow tumble, a measurement every 5 steps, one row starting late and one
    measurement NaN (sanitised away)."""
    rng = np.random.default_rng(0)
    t = np.arange(steps) * 0.1
    angle = 0.05 * t[None, :] + rng.uniform(0, 1, (batch, 1))
    q = np.stack([np.cos(angle / 2), np.sin(angle / 2), np.zeros_like(angle), np.zeros_like(angle)], -1)
    r = 0.01 * t[None, :, None] * np.ones((batch, 1, 3))
    z = np.concatenate([q, r], -1) + rng.normal(0, 1e-3, (batch, steps, 7))
    mask = np.zeros((batch, steps), dtype=bool)
    mask[:, ::5] = True
    mask[0, :10] = False
    z[1, 5, 0] = np.nan
    return torch.from_numpy(z), torch.from_numpy(mask)


@pytest.mark.parametrize("model_name", model_names())
@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_run_and_gradient_make_no_tensor_off_the_inputs_device(
    gpu_path: None, on_meta: None, variant: str, model_name: str
) -> None:
    z, mask = _episodes()
    model = make_model(model_name, inertia=(0.153, 0.143, 0.162) if model_name == "rigid-body" else None)
    filt = make_filter(variant, model=model)
    filt.set_gate(0.9999)
    layout = filt.layout
    q_std = torch.tensor(layout.q_default, dtype=torch.float64, device="cpu", requires_grad=True)
    r_std = torch.tensor(layout.r_default, dtype=torch.float64, device="cpu")
    p0_std = torch.tensor(layout.p0_default, dtype=torch.float64, device="cpu")
    noise = NoiseParameters.from_std(q_std, r_std, p0_std)
    with torch.no_grad():  # (preallocated output series)
        evaluated = filt.run(noise, z, mask, dt=0.1)
    result = filt.run(noise, z, mask, dt=0.1)  # (series concatenated under autograd)
    for outputs in (evaluated, result):
        assert outputs.means.device.type == "cpu" and outputs.covariances is not None
        assert bool(torch.isfinite(outputs.means).all())
    result.means[:, 10:].square().sum().backward()
    assert q_std.grad is not None and bool(torch.isfinite(q_std.grad).all())


def test_time_varying_noise_and_a_given_initial_state_stay_on_the_inputs_device(
    gpu_path: None, on_meta: None
) -> None:
    z, mask = _episodes()
    filt = make_filter("ekf")
    layout = filt.layout
    cpu = dict(dtype=torch.float64, device="cpu")
    scale = torch.linspace(0.5, 2.0, z.shape[1], **cpu)[None, :, None].expand(z.shape[0], -1, 1).requires_grad_()
    q_std = torch.tensor(layout.q_default, **cpu) * scale
    noise = NoiseParameters.from_std(q_std, torch.tensor(layout.r_default, **cpu), torch.tensor(layout.p0_default, **cpu))
    initial = FilterState(torch.cat((z[:, 1, :7], torch.zeros(z.shape[0], 6, **cpu)), 1),
                          torch.eye(13, **cpu).expand(z.shape[0], 13, 13) * 0.01)
    result = filt.run(noise, z.nan_to_num(), mask, dt=0.1, initial=initial)
    result.means.sum().backward()
    assert scale.grad is not None and bool(torch.isfinite(scale.grad).all())
