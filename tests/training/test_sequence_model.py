"""The Trainer trains a SequenceModel (a module with its own recursion, e.g. KalmanNet) through
its ``sequence_mse``; with ``max_grad_norm`` it counts clipped steps and skips (and counts) a
batch whose gradient is not finite, so the weights never become NaN."""

from __future__ import annotations

import math
from typing import Any

import pytest
import torch
from torch import Tensor, nn

from fkn_bench.filters import make_filter
from fkn_bench.scenarios import get_scenario
from fkn_bench.training import Sequences, SequenceModel, TrainConfig, Trainer, TrainingData

SHORT = get_scenario("ds1", n_steps=2000)


class Offset(SequenceModel):
    """Estimates = measured pose plus a learned offset (zeros for the twist); with ``poison`` the
    first ``poison`` losses have an infinite gradient (``sqrt`` at 0)."""

    def __init__(self, poison: int = 0) -> None:
        super().__init__()
        self.offset = nn.Parameter(torch.full((13,), 0.5, dtype=torch.float64))
        self.poison = poison

    def run_means(self, measurements: Tensor, mask: Tensor, *, dt: float) -> Tensor:
        z = torch.nan_to_num(measurements)
        return torch.cat((z, torch.zeros(*z.shape[:2], 6, dtype=z.dtype)), -1) + self.offset

    def sequence_mse(self, sequences: Sequences, *, dt: float, loss_cut: int) -> Tensor:
        error = self.run_means(sequences.measurements, sequences.mask, dt=dt)[:, loss_cut:] - sequences.truth[:, loss_cut:]
        loss = error.square().mean()
        if self.training and self.poison > 0:
            self.poison -= 1
            loss = loss + torch.sqrt(self.offset[0] - self.offset[0].detach())  # value 0, gradient inf
        return loss

    def describe(self) -> dict[str, Any]:
        return {"offset": self.offset.tolist()}


@pytest.fixture(scope="module")
def data() -> TrainingData:
    return TrainingData(SHORT, window=200, train_measurement_every=10)


def _trainer(data: TrainingData, model: SequenceModel, **overrides: Any) -> Trainer:
    config = TrainConfig(**{"window": 200, "loss_cut": 50, "episodes": 1, "epochs": 3, "lr": 0.05,
                            "windows_per_batch": 4, **overrides})
    return Trainer(model, make_filter("ekf"), data, config)


def test_a_sequence_model_trains_through_its_own_recursion(data: TrainingData) -> None:
    trainer = _trainer(data, Offset())
    history = trainer.fit(progress=False)
    assert history[-1].val_loss < history[0].val_loss
    assert trainer.gradient_steps == {"taken": 6, "clipped": 0, "skipped_nonfinite": 0}
    assert history[-1].parameters == {"gradient_steps_taken": 6.0, "gradient_steps_clipped": 0.0,
                                      "gradient_steps_skipped_nonfinite": 0.0}


def test_clipping_is_counted_and_non_finite_gradients_skip_the_step(data: TrainingData) -> None:
    model = Offset(poison=2)
    trainer = _trainer(data, model, max_grad_norm=1e-3)
    trainer.fit(progress=False)
    assert trainer.gradient_steps["skipped_nonfinite"] == 2
    assert trainer.gradient_steps["taken"] == 4 and trainer.gradient_steps["clipped"] == 4
    assert torch.isfinite(model.offset).all() and all(math.isfinite(r.train_loss) for r in trainer.history)
