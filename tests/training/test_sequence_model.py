"""The Trainer trains a SequenceModel (a module with its own recursion, e.g. KalmanNet) through
its ``sequence_mse``; with ``max_grad_norm`` it counts clipped steps; a batch whose loss or
gradient is not finite takes no step, and undoes the step that led there (halving the learning
rate) or is skipped at the starting weights, so the weights never become NaN."""

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
    assert trainer.gradient_steps == {"taken": 6, "clipped": 0, "skipped_nonfinite": 0, "rolled_back": 0}
    assert history[-1].parameters == {"gradient_steps_taken": 6.0, "gradient_steps_clipped": 0.0,
                                      "gradient_steps_skipped_nonfinite": 0.0, "gradient_steps_rolled_back": 0.0}


def test_clipping_is_counted_and_non_finite_gradients_skip_the_step(data: TrainingData) -> None:
    model = Offset(poison=2)
    trainer = _trainer(data, model, max_grad_norm=1e-3)
    trainer.fit(progress=False)
    assert trainer.gradient_steps["skipped_nonfinite"] == 2
    assert trainer.gradient_steps["taken"] == 4 and trainer.gradient_steps["clipped"] == 4
    assert torch.isfinite(model.offset).all() and all(math.isfinite(r.train_loss) for r in trainer.history)


class Cliff(Offset):
    """``Offset`` whose training loss has an infinite gradient (or, with ``infinite_loss``, is
    infinite) once the first offset falls below ``edge``, and whose validation loss is then
    infinite: a step that crosses it must be undone (or, the last of an epoch, not be the best)."""

    def __init__(self, edge: float, *, infinite_loss: bool = False) -> None:
        super().__init__()
        self.edge, self.infinite_loss = edge, infinite_loss

    def sequence_mse(self, sequences: Sequences, *, dt: float, loss_cut: int) -> Tensor:
        loss = super().sequence_mse(sequences, dt=dt, loss_cut=loss_cut)
        if float(self.offset[0].detach()) < self.edge:
            if self.infinite_loss or not self.training:  # validation sees the divergence too
                return loss * math.inf
            return loss + torch.sqrt(self.offset[0] - self.offset[0].detach())  # value 0, gradient inf
        return loss


@pytest.mark.parametrize("infinite_loss", [False, True], ids=["infinite-gradient", "infinite-loss"])
def test_a_step_into_a_non_finite_region_is_undone_and_the_learning_rate_halved(data: TrainingData,
                                                                               infinite_loss: bool) -> None:
    # Adam's first step moves the offset by about lr = 0.05, from 0.5 to 0.45: past the edge
    model = Cliff(edge=0.46, infinite_loss=infinite_loss)
    trainer = _trainer(data, model, max_grad_norm=10.0)
    trainer.fit(progress=False)
    steps = trainer.gradient_steps
    assert steps["rolled_back"] >= 1 and steps["skipped_nonfinite"] == 0
    assert float(model.offset[0].detach()) >= model.edge  # every crossing undone
    assert torch.isfinite(model.offset).all() and all(math.isfinite(r.train_loss) for r in trainer.history)
    assert trainer.optimizer.param_groups[0]["lr"] == pytest.approx(0.05 * 0.5 ** steps["rolled_back"])
    # Adam's moments were restored with the weights: it counts only the steps that stand
    assert int(trainer.optimizer.state[model.offset]["step"]) == steps["taken"] - steps["rolled_back"]
    assert trainer.history[-1].parameters["gradient_steps_rolled_back"] == steps["rolled_back"]


def test_an_epoch_without_a_finite_loss_at_the_starting_weights_is_an_error(data: TrainingData) -> None:
    model = Cliff(edge=1.0, infinite_loss=True)  # diverges from the start: nothing to undo
    with pytest.raises(FloatingPointError, match="no finite training loss in epoch 1"):
        _trainer(data, model).fit(progress=False)
    assert float(model.offset[0].detach()) == 0.5


@pytest.mark.parametrize("factor", [None, 1.0], ids=["off", "restart"])
def test_a_divergent_epoch_restarts_from_the_best_weights_when_asked(data: TrainingData, factor: float | None) -> None:
    model = Offset()
    trainer = _trainer(data, model, restart_on_divergence=factor)
    validate, seen, at_epoch_2 = trainer.validate, [], {}

    def spiking() -> tuple[float, float]:  # epoch 2's validation loss jumps a million-fold (finite)
        loss, rmse = validate()
        seen.append(loss)
        return (loss * 1e6 if len(seen) == 2 else loss), rmse

    def look(epoch: int, history: list) -> bool:  # type: ignore[type-arg]
        at_epoch_2.setdefault("after_1", model.offset.detach().clone())  # epoch 1: the best so far
        if epoch == 2:
            at_epoch_2.update(offset=model.offset.detach().clone(), adam=len(trainer.optimizer.state))
        return False

    trainer.validate = spiking  # type: ignore[method-assign]
    trainer.fit(on_epoch=look, progress=False)
    if factor is None:  # the spike is just a bad epoch
        assert trainer.divergence_restarts == 0 and trainer.optimizer.param_groups[0]["lr"] == 0.05
        assert not torch.equal(at_epoch_2["offset"], at_epoch_2["after_1"])  # it trained on from epoch 2's
        return
    assert trainer.divergence_restarts == 1 and trainer.best_epoch != 2
    assert trainer.optimizer.param_groups[0]["lr"] == pytest.approx(0.05 * trainer.config.scheduler_factor)
    assert torch.equal(at_epoch_2["offset"], at_epoch_2["after_1"])  # back to epoch 1's weights
    assert at_epoch_2["adam"] == 0  # with Adam's moments afresh


class Spike(Offset):
    """``Offset`` whose training loss is a million times larger (finite) on batch ``at``."""

    def __init__(self, at: int) -> None:
        super().__init__()
        self.at, self.batches = at, 0

    def sequence_mse(self, sequences: Sequences, *, dt: float, loss_cut: int) -> Tensor:
        loss = super().sequence_mse(sequences, dt=dt, loss_cut=loss_cut)
        if self.training:
            self.batches += 1
            return loss * 1e6 if self.batches == self.at else loss
        return loss


@pytest.mark.parametrize("factor", [None, 1.0], ids=["off", "guarded"])
def test_no_step_is_taken_on_a_finite_loss_spike_when_asked(data: TrainingData, factor: float | None) -> None:
    model = Spike(at=3)  # two batches an epoch: the first batch of epoch 2, after a best exists
    trainer = _trainer(data, model, restart_on_divergence=factor)
    trainer.fit(progress=False)
    steps = trainer.gradient_steps
    if factor is None:  # the spike is trained on and averaged into epoch 2's loss
        assert trainer.loss_spikes == 0 and steps == {"taken": 6, "clipped": 0, "skipped_nonfinite": 0, "rolled_back": 0}
        assert trainer.history[1].train_loss > 100 * trainer.history[0].train_loss
        return
    assert trainer.loss_spikes == 1 and steps == {"taken": 5, "clipped": 0, "skipped_nonfinite": 0, "rolled_back": 0}
    assert trainer.optimizer.param_groups[0]["lr"] == 0.05  # a spike is the batch's, not the last step's
    assert trainer.history[1].train_loss < 10 * trainer.history[0].train_loss  # left out of the mean
    assert int(trainer.optimizer.state[model.offset]["step"]) == 5


def test_restart_on_divergence_must_be_a_positive_factor() -> None:
    with pytest.raises(ValueError, match="restart_on_divergence must be None or a finite number > 0"):
        TrainConfig(restart_on_divergence=0.0)
