"""The sequential reference trainer: FlexKalmanNet trained the straightforward way.

This is the implementation the real trainer is measured against (``fkn-bench bench train``): it
processes the training windows one after another, and within a window one step at a time, calling
the network on the current measurement at every step (the last valid one on steps without a
measurement) and running textbook EKF equations on a single sequence, then takes one optimiser
step per window. It learns the same thing as :class:`~fkn_bench.training.Trainer` (the same
parameter set, objective, loss cut and data) and is written plainly on purpose: dense ``H``,
explicit ``F`` from the paper's ``Omega``/``Theta`` matrices, an explicit inverse of ``S``, the
Joseph form, then the quaternion renormalisation and covariance projection.

It exists to make the speed-up of the batched trainer measurable in one run; it is not used for
training.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import torch
from torch import Tensor

from fkn_bench.flexkalmannet.network import FlexKalmanNet
from fkn_bench.geometry import quaternion_xp as qt
from fkn_bench.linalg import symmetrize
from fkn_bench.training.data import Sequences, TrainingData
from fkn_bench.training.objectives import aligned_state_error

__all__ = ["ReferenceEpoch", "sequential_reference_epoch"]


@dataclass(frozen=True)
class ReferenceEpoch:
    """Timing and loss of one reference epoch."""

    seconds: float
    windows: int
    steps: int
    mean_loss: float


def _textbook_step(x: Tensor, P: Tensor, z: Tensor | None, Q: Tensor, R: Tensor, dt: float) -> tuple[Tensor, Tensor]:
    """One EKF step of the paper's model on one sequence (``x (13,)``, ``P (13, 13)``)."""
    q, r, w, v = x[0:4], x[4:7], x[7:10], x[10:13]
    theta = qt.theta_matrix(q)
    q_new = q + 0.5 * dt * theta @ w
    x = torch.cat((q_new, r + dt * v, w, v))
    F = torch.eye(13, dtype=x.dtype)
    F = F + torch.block_diag(0.5 * dt * qt.omega_matrix(w), torch.zeros(9, 9, dtype=x.dtype))
    F = F + torch.nn.functional.pad(0.5 * dt * theta, (7, 3, 0, 9))
    F = F + torch.nn.functional.pad(dt * torch.eye(3, dtype=x.dtype), (10, 0, 4, 6))
    P = F @ P @ F.T + Q
    if z is not None:
        H = torch.cat((torch.eye(7, dtype=x.dtype), torch.zeros(7, 6, dtype=x.dtype)), dim=1)
        if torch.dot(z[0:4], x[0:4]) < 0:
            z = torch.cat((-z[0:4], z[4:7]))
        S = H @ P @ H.T + R
        K = P @ H.T @ torch.linalg.inv(S)
        x = x + K @ (z - H @ x)
        A = torch.eye(13, dtype=x.dtype) - K @ H
        P = A @ P @ A.T + K @ R @ K.T
        norm = torch.linalg.norm(x[0:4])
        unit = x[0:4] / norm
        T = torch.block_diag((torch.eye(4, dtype=x.dtype) - torch.outer(unit, unit)) / norm, torch.eye(9, dtype=x.dtype))
        x = torch.cat((unit, x[4:]))
        P = T @ P @ T.T
    return x, symmetrize(P)  # once per step: P leaves symmetric after a prediction or an update


def _window_loss(model: FlexKalmanNet, window: Sequences, index: int, dt: float, loss_cut: int) -> Tensor:
    z_all, mask, truth = window.measurements[index], window.mask[index], window.truth[index]
    steps = z_all.shape[0]
    estimates = []
    x = P = None
    last_raw: Tensor | None = None
    for t in range(steps):
        z = z_all[t] if bool(mask[t]) else None
        if z is not None:
            z = torch.cat((z[0:4] / torch.linalg.norm(z[0:4]), z[4:7]))
            last_raw = model._outputs(z[None])[0]  # the network, every step with a measurement
        raw = last_raw if last_raw is not None else model.deployed_raw()
        noise = model.parameter_set.to_noise(raw)
        if x is None:
            if z is None:
                estimates.append(None)
                continue
            x = torch.cat((z, torch.zeros(6, dtype=z.dtype)))
            P = noise.initial
        else:
            x, P = _textbook_step(x, P, z, noise.process, noise.measurement, dt)
        estimates.append(x)
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
