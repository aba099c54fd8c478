"""A linear Gaussian benchmark of KalmanNet's paper (its linear-model experiments, a
model in canonical form, at a small size): data, the Kalman filter on it, and KalmanNet trained by the shared Trainer.

``x' = A x + w``, ``A = [[1, 1], [0, 1]]``, ``w ~ N(0, q^2 I)``; ``y = x + v``, ``v ~ N(0, r^2 I)``
(``H = I``), ``q = 0.1``, ``r = 1`` (``q^2 / r^2 = -20 dB``), 50-step sequences from
``x0 ~ N(0, I)``. Both filters initialise from the first measurement (``x0 = y0``; the Kalman
filter with ``P0 = R``, the posterior of a flat prior), so the Kalman filter with the true ``Q``
and ``R`` is the optimal (MMSE) filter here. MSE is reported in dB (``10 log10 MSE``), as the
paper does.

The tests (``tests/kalmannet/test_linear_gaussian.py``) check the paper's claims on it; print
the numbers with ``python -m fkn_bench.kalmannet.linear``.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import numpy as np
import torch

from fkn_bench.filters import ExtendedKalmanFilter, make_filter
from fkn_bench.models.linear import LinearGaussianModel
from fkn_bench.models.noise import NoiseParameters
from fkn_bench.kalmannet.checkpoint import build_model
from fkn_bench.kalmannet.config import KalmanNetConfig
from fkn_bench.kalmannet.recursion import KalmanNet
from fkn_bench.runtime import torch_threads
from fkn_bench.training import Sequences, Trainer

A = np.array([[1.0, 1.0], [0.0, 1.0]])
H = np.eye(2)
Q_STD, R_STD = 0.1, 1.0
STEPS = 50
MODEL = LinearGaussianModel(A, H)
__all__ = ["A", "H", "Q_STD", "R_STD", "STEPS", "MODEL", "CONFIG", "ArrayData", "simulate", "mse_db", "kalman_means",
           "train_kalmannet", "kalmannet_means"]
CONFIG = KalmanNetConfig(
    window=STEPS, loss_cut=0, epochs=15, patience=15, lr=1e-3, windows_per_batch=50, max_grad_norm=1.0,
    in_mult=5, out_mult=10, network_dtype="float64", detach_every=None, seed=0,
)


def simulate(sequences: int, seed: int) -> Sequences:
    """``sequences`` trajectories of the model (numpy generator ``seed``), every step measured."""
    rng = np.random.default_rng(seed)
    x = rng.normal(0.0, 1.0, (sequences, 2))
    states, measurements = [], []
    for t in range(STEPS):
        if t:
            x = x @ A.T + Q_STD * rng.normal(size=(sequences, 2))
        states.append(x)
        measurements.append(x @ H.T + R_STD * rng.normal(size=(sequences, 2)))
    return Sequences(torch.tensor(np.stack(measurements, 1)), torch.ones(sequences, STEPS, dtype=torch.bool),
                     torch.tensor(np.stack(states, 1)))


@dataclass
class ArrayData:
    """The parts of :class:`~fkn_bench.training.TrainingData` the Trainer reads, for arrays."""

    train: Sequences
    val: Sequences
    window: int = STEPS
    scenario: Any = field(default_factory=lambda: SimpleNamespace(dt=1.0))

    def batches(self, windows_per_batch: int, generator: torch.Generator) -> Iterator[Sequences]:
        order = torch.randperm(self.train.batch_size, generator=generator)
        for start in range(0, self.train.batch_size, windows_per_batch):
            yield self.train.select(order[start : start + windows_per_batch])


def mse_db(means: torch.Tensor, truth: torch.Tensor) -> float:
    """``10 log10`` of the mean squared error over every step and component."""
    return 10.0 * math.log10(float((means - truth).square().mean()))


def kalman_means(data: Sequences, q_std: float, r_std: float) -> torch.Tensor:
    """The Kalman filter assuming ``Q = q_std^2 I``, ``R = r_std^2 I`` (``P0 = R``)."""
    noise = NoiseParameters.from_std([q_std] * 2, [r_std] * 2, [r_std] * 2)
    with torch.no_grad():
        return ExtendedKalmanFilter(model=MODEL).run(noise, data.measurements, data.mask, dt=1.0).means


def train_kalmannet(train: Sequences, val: Sequences, config: KalmanNetConfig = CONFIG) -> tuple[KalmanNet, Trainer]:
    """KalmanNet on :data:`MODEL`, trained by :class:`~fkn_bench.training.Trainer` (the loop of
    every trainable estimator) with ``config``; returns the network (best epoch) and the trainer."""
    net = build_model(config, model=MODEL)
    trainer = Trainer(net, make_filter("ekf"), ArrayData(train, val), config)  # type: ignore[arg-type]
    torch.manual_seed(config.seed)
    with torch_threads(1):
        trainer.fit(progress=False)
    return net, trainer


def kalmannet_means(net: KalmanNet, data: Sequences) -> torch.Tensor:
    """KalmanNet's estimates ``(B, T, 2)`` of ``data``."""
    with torch.no_grad():
        return net.run_means(data.measurements, data.mask, dt=1.0)


if __name__ == "__main__":  # pragma: no cover - prints the numbers of the report
    import time

    train, val, test = simulate(200, 0), simulate(100, 1), simulate(200, 2)
    began = time.perf_counter()
    net, trainer = train_kalmannet(train, val)
    print(f"trained in {time.perf_counter() - began:.1f} s, {len(trainer.history)} epochs, best {trainer.best_epoch}, "
          f"gradient steps {trainer.gradient_steps}")
    print(f"KF (true Q, R)            {mse_db(kalman_means(test, Q_STD, R_STD), test.truth):.3f} dB")
    print(f"KF (R assumed 10x small)  {mse_db(kalman_means(test, Q_STD, 0.1 * R_STD), test.truth):.3f} dB")
    print(f"KalmanNet                 {mse_db(kalmannet_means(net, test), test.truth):.3f} dB")
