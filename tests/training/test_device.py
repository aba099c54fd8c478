"""Training runs on ``config.device`` (``fkn-bench train --device cuda`` where a GPU exists).

As in ``tests/filters/test_device.py``, a machine without a GPU checks what would break on one:
the losses and gradients of a training step, and the validation pass, are computed with torch's
default device set to ``meta`` while the model and data stay on the CPU, so any tensor made
without following its inputs' device raises. The optimiser step runs outside (torch's Adam keeps
its step counter on the default device).
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager
from typing import Any

import pytest
import torch

from fkn_bench.filters import ParameterSet, make_filter
from fkn_bench.scenarios import get_scenario
from fkn_bench.training import DirectParameters, TrainConfig, Trainer, TrainingData
from fkn_bench.training.pipeline import trainable

SHORT = get_scenario("ds1", n_steps=2000)


@pytest.fixture(scope="module")
def data() -> TrainingData:
    return TrainingData(SHORT, window=200)


@pytest.fixture
def steps_on_meta(gpu_path: None, meta_default_device: Callable[[], AbstractContextManager[None]],
                  monkeypatch: pytest.MonkeyPatch) -> None:
    """The GPU's filter step, with training steps and validation computed under a ``meta``
    default device."""
    def on_meta(method: Callable[..., Any]) -> Callable[..., Any]:
        def wrapped(*args: Any, **kwargs: Any) -> Any:
            with meta_default_device():
                return method(*args, **kwargs)

        return wrapped

    monkeypatch.setattr(Trainer, "_backward", on_meta(Trainer._backward))
    monkeypatch.setattr(Trainer, "validate", on_meta(Trainer.validate))


CONFIGS = {
    "direct-ekf": None,
    "flexkalmannet": {"hidden": 32, "layers": 2},
    "flexkalmannet-time-varying": {"hidden": 32, "layers": 2, "mode": "time_varying"},
    "kalmannet": {"out_mult": 2, "detach_every": 100},
    "recursive-kalmannet": {"out_mult": 2, "detach_every": 100},
}


@pytest.mark.parametrize("name", sorted(CONFIGS))
def test_a_training_epoch_makes_no_tensor_off_the_models_device(
    data: TrainingData, steps_on_meta: None, name: str
) -> None:
    options = CONFIGS[name]
    common = {"window": 200, "loss_cut": 50, "epochs": 1, "windows_per_batch": 4}
    if options is None:
        variant = make_filter("ekf")
        model: Any = DirectParameters(ParameterSet(variant.layout))
        config: Any = TrainConfig(lr=0.01, **common)
    else:
        declared = trainable(name.removesuffix("-time-varying"))
        config = declared.config({**common, **options})
        model = declared.build(config, data)
        variant = config.train_config().build_filter(SHORT)
    trainer = Trainer(model, variant, data, config.train_config())
    history = trainer.fit(progress=False)
    assert len(history) == 1 and trainer.gradient_steps["taken"] >= 1
    assert torch.isfinite(torch.tensor(history[0].val_rmse))


def test_the_device_is_checked_where_it_is_named(data: TrainingData) -> None:
    with pytest.raises(ValueError, match="unknown device 'gpu'"):
        TrainConfig(device="gpu")
    assert TrainConfig().to_dict().get("device") is None  # the CPU's configs read as before
    assert TrainConfig(device="cuda").to_dict()["device"] == "cuda"
    if not torch.cuda.is_available():
        variant = make_filter("ekf")
        with pytest.raises(ValueError, match="CUDA is not available here"):
            Trainer(DirectParameters(ParameterSet(variant.layout)), variant, data, TrainConfig(device="cuda", window=200, loss_cut=50))
    assert data.to("cpu") is data
