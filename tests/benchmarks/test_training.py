"""One FlexKalmanNet training epoch (the paper's network and windows) and the sequential reference
trainer on one window (``fkn-bench bench train`` prints their ratio over a whole epoch)."""

from __future__ import annotations

import copy
from typing import Any

import pytest

from fkn_bench.filters import make_filter
from fkn_bench.flexkalmannet.checkpoint import build_model
from fkn_bench.flexkalmannet.config import FlexKalmanNetConfig
from fkn_bench.flexkalmannet.reference import sequential_reference_epoch
from fkn_bench.gates.speed import suite_device, synchronized
from fkn_bench.training import Trainer, TrainingData

DEVICE = suite_device()


@pytest.fixture(scope="module")
def setup() -> tuple[FlexKalmanNetConfig, TrainingData, Any]:
    config = FlexKalmanNetConfig(device=str(DEVICE))
    data = TrainingData("ds1", window=config.window, stride=config.stride,
                        train_measurement_every=config.train_measurement_every, episodes=config.episodes)
    return config, data, build_model(config, data)


def test_training_epoch(benchmark: Any, setup: Any) -> None:
    config, data, fresh = setup
    trainer = Trainer(copy.deepcopy(fresh), make_filter(config.variant), data, config.train_config())
    benchmark.pedantic(synchronized(trainer.run_epoch), rounds=3, warmup_rounds=1)
    on = "" if DEVICE.type == "cpu" else f", on {DEVICE}"
    benchmark.extra_info.update(steps=data.n_windows * data.window,
           what=f"Trainer.run_epoch, {data.n_windows} windows of {data.window}, batches of {config.windows_per_batch}{on}")


def test_sequential_reference_window(benchmark: Any, setup: Any) -> None:
    config, data, fresh = setup
    model = copy.deepcopy(fresh)
    benchmark.pedantic(
        lambda: sequential_reference_epoch(model, data, lr=config.lr, loss_cut=config.loss_cut, max_windows=1),
        rounds=2, warmup_rounds=0,
    )
    benchmark.extra_info.update(steps=data.window, what=f"sequential reference trainer, 1 window of {data.window}")
