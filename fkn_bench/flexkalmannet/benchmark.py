"""Training speed: one epoch of the batched trainer against the sequential reference.

Both learn FlexKalmanNet with the same configuration, parameter set, data windows, objective and
loss cut; the reference (:mod:`fkn_bench.flexkalmannet.reference`) runs the windows one after
another and the network at every step, the trainer runs all windows of a batch through the
filter at once. Both start from the same freshly built model. Timed in one process, one after the
other, with the same thread count, so the ratio is meaningful on a noisy machine.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

from fkn_bench.flexkalmannet.checkpoint import build_model
from fkn_bench.flexkalmannet.config import FlexKalmanNetConfig
from fkn_bench.flexkalmannet.reference import ReferenceEpoch, sequential_reference_epoch
from fkn_bench.runtime import torch_threads
from fkn_bench.scenarios import Scenario, get_scenario
from fkn_bench.training import Trainer
from fkn_bench.training.data import TrainingData, training_data

__all__ = ["TrainingSpeed", "measure_training_speed", "training_benchmark", "time_varying_ratio"]


@dataclass(frozen=True)
class TrainingSpeed:
    """Seconds per epoch of both trainers and their ratio."""

    scenario: str
    window: int
    train_measurement_every: int
    windows: int
    reference_windows_timed: int
    reference_seconds_per_epoch: float
    trainer_seconds_per_epoch: float
    trainer_epochs_timed: int

    @property
    def ratio(self) -> float:
        return self.reference_seconds_per_epoch / self.trainer_seconds_per_epoch

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "ratio": self.ratio}


def training_benchmark(
    scenario: Scenario, config: FlexKalmanNetConfig, *, reference_windows: int | None = None
) -> tuple[TrainingData, Trainer, Callable[[], ReferenceEpoch]]:
    """``(data, trainer, reference)``: the batched trainer and a call running the sequential
    reference epoch (its first ``reference_windows`` windows), each on its own copy of one freshly
    built model (:func:`measure_training_speed` and the speed gate's ``train-epoch`` check)."""
    data = training_data(scenario, config)
    fresh = build_model(config, data)
    trainer = Trainer(copy.deepcopy(fresh), config.build_filter(scenario), data, config.train_config())
    reference_model = copy.deepcopy(fresh)

    def reference() -> ReferenceEpoch:
        return sequential_reference_epoch(reference_model, data, lr=config.lr, loss_cut=config.loss_cut,
                                          max_windows=reference_windows)

    return data, trainer, reference


def measure_training_speed(
    scenario: str | Scenario = "ds1",
    config: FlexKalmanNetConfig | None = None,
    *,
    reference_windows: int | None = None,
    trainer_epochs: int = 3,
) -> TrainingSpeed:
    """Time the reference epoch (or ``reference_windows`` of its windows, scaled to an epoch)
    and the median of ``trainer_epochs`` trainer epochs."""
    scenario = get_scenario(scenario)
    config = config if config is not None else FlexKalmanNetConfig()
    data, trainer, run_reference = training_benchmark(scenario, config, reference_windows=reference_windows)
    with torch_threads(config.threads):
        durations = []
        for _ in range(trainer_epochs):
            began = time.perf_counter()
            trainer.run_epoch()
            durations.append(time.perf_counter() - began)
        reference = run_reference()
    durations.sort()
    return TrainingSpeed(
        scenario=scenario.name,
        window=data.window,
        train_measurement_every=data.train_measurement_every,
        windows=data.n_windows,
        reference_windows_timed=reference.windows,
        reference_seconds_per_epoch=reference.seconds * data.n_windows / reference.windows,
        trainer_seconds_per_epoch=durations[len(durations) // 2],
        trainer_epochs_timed=trainer_epochs,
    )


def time_varying_ratio(scenario: str | Scenario = "ds1", config: FlexKalmanNetConfig | None = None, *,
                       epochs: int = 3) -> tuple[float, float]:
    """Median seconds per training epoch of the trainer in constant and in time-varying mode
    (the same configuration otherwise), timed alternately in this process: ``(constant,
    time_varying)``. Time-varying training runs the network on every valid measurement and the
    filter on per-step noise; ``fkn-bench bench train --time-varying`` prints their ratio."""
    scenario = get_scenario(scenario)
    config = config if config is not None else FlexKalmanNetConfig()
    trainers = [training_benchmark(scenario, config.replace(mode=mode))[1] for mode in ("constant", "time_varying")]
    times: list[list[float]] = [[], []]
    with torch_threads(config.threads):
        for trainer in trainers:
            trainer.run_epoch()  # warm-up
        for _ in range(epochs):
            for index, trainer in enumerate(trainers):
                began = time.perf_counter()
                trainer.run_epoch()
                times[index].append(time.perf_counter() - began)
    constant, varying = (sorted(t)[len(t) // 2] for t in times)
    return constant, varying
