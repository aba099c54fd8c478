"""The sequential reference trainer: FlexKalmanNet trained the straightforward way.

This is the implementation the real trainer is measured against (``fkn-bench bench train``): it
processes the training windows one after another, and within a window one step at a time, calling
the network on the current measurement at every step (the last valid one on steps without a
measurement) and running the EKF's step functions
(:class:`~fkn_bench.filters.ExtendedKalmanFilter` ``predict``/``update``) on a single sequence
(batch 1), then takes one optimiser step per window. It learns the same thing as
:class:`~fkn_bench.training.Trainer` (the same parameter set, objective, loss cut and data); what
it lacks is the batching over windows and the parameters evaluated once per window.

It exists to make the speed-up of the batched trainer measurable in one run; it is not used for
training.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import torch
from torch import Tensor

from fkn_bench.filters import ExtendedKalmanFilter, FilterState
from fkn_bench.flexkalmannet.network import FlexKalmanNet
from fkn_bench.training.data import Sequences, TrainingData
from fkn_bench.training.objectives import aligned_state_error

__all__ = ["ReferenceEpoch", "sequential_reference_epoch"]

_EKF = ExtendedKalmanFilter()


@dataclass(frozen=True)
class ReferenceEpoch:
    """Timing and loss of one reference epoch."""

    seconds: float
    windows: int
    steps: int
    mean_loss: float


def _window_loss(model: FlexKalmanNet, window: Sequences, index: int, dt: float, loss_cut: int) -> Tensor:
    z_all, mask, truth = window.measurements[index], window.mask[index], window.truth[index]
    steps = z_all.shape[0]
    estimates = []
    state: FilterState | None = None
    last_raw: Tensor | None = None
    for t in range(steps):
        z, usable = _EKF.model.sanitize(z_all[t : t + 1], mask[t : t + 1])  # (1, 7): the model's rule
        if not bool(usable[0]):
            z = None
        else:
            last_raw = model._outputs(z)[0]  # the network, every step with a measurement
        raw = last_raw if last_raw is not None else model.deployed_raw()
        noise = model.parameter_set.to_noise(raw)
        if state is None:
            if z is None:
                estimates.append(None)
                continue
            state = _EKF.initial_state(z, noise.initial)
        else:
            state = _EKF.predict(state, noise.process, dt)
            if z is not None:
                state = _EKF.update(state, z, noise.measurement)[0]
        estimates.append(state.mean[0])
    kept = [(t, e) for t, e in enumerate(estimates) if e is not None and t >= loss_cut]
    means = torch.stack([e for _, e in kept])
    target = truth[[t for t, _ in kept]]
    return aligned_state_error(means, target).square().mean()


def sequential_reference_epoch(
    model: FlexKalmanNet,
    data: TrainingData,
    *,
    lr: float,
    loss_cut: int,
    max_windows: int | None = None,
) -> ReferenceEpoch:
    """One epoch (or its first ``max_windows`` windows) of the sequential reference trainer."""
    optimizer = torch.optim.Adam(model.parameters(), lr=lr)
    windows = data.n_windows if max_windows is None else min(max_windows, data.n_windows)
    began = time.perf_counter()
    total = 0.0
    for index in range(windows):
        optimizer.zero_grad(set_to_none=True)
        loss = _window_loss(model, data.train, index, data.scenario.dt, loss_cut)
        loss.backward()
        optimizer.step()
        total += float(loss.detach())
    seconds = time.perf_counter() - began
    return ReferenceEpoch(seconds=seconds, windows=windows, steps=windows * data.window, mean_loss=total / windows)
