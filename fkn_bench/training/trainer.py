"""A training loop for anything that produces filter parameters, trained through the filter.

:class:`NoiseModel` is the interface: ``window_raw(sequences)`` gives the unconstrained parameter
vector(s) for a batch of sequences (``(B, size)`` constant per sequence, or ``(B, T, size)``
time-varying) and ``deployed_raw()`` the constant vector used after training. FlexKalmanNet's
network and the directly tuned EKF (:class:`DirectParameters`) both implement it, so they share
this loop: Adam (or full-batch L-BFGS), ``ReduceLROnPlateau`` on the validation loss, early
stopping after ``patience`` epochs without improvement, fixed seeds, the best epoch's weights
restored at the end.

With Adam one epoch is one pass over the training windows in shuffled batches; each batch runs
through the filter variant (any of ekf, ukf, mekf) in parallel and takes one optimiser step. With
L-BFGS one epoch is one ``torch.optim.LBFGS`` step (up to ``lbfgs_iterations`` iterations,
strong-Wolfe line search) on all training windows at once. Validation runs the variant with the deployed parameters over the whole val split and reports the 13-state RMSE
(supervised objective) or the innovation NLL (``nll``, which uses no ground truth for model
selection; the RMSE is logged as a diagnostic only).

A :class:`SequenceModel` (KalmanNet) brings its own differentiable recursion instead: the loop
calls its ``sequence_loss`` where it would run the variant, and everything else (optimiser,
scheduler, early stopping, seeds, resume) is the same. With ``max_grad_norm`` set, gradient norms
are clipped and the steps whose norm was above it are counted.

Non-finite losses and gradients (Adam): the weights never step to NaN. A batch whose training loss
or gradient norm is not finite takes no step. If the weights have moved since the last batch
with a finite gradient, the step that moved them is undone (weights and Adam's moments return
to just before it) and the learning rate is halved, since such a step left the recursion where it
diverges (counted ``rolled_back``; a learned filter's usual failure, the recurrent gain pushing
the filter off its measurements, cf. KalmanNet's issues #23 and #27). Otherwise (the starting
weights, or a step just undone) the batch is skipped (``skipped_nonfinite``); an epoch with no
finite loss and no step to undo raises ``FloatingPointError``. The counts are in
:attr:`Trainer.gradient_steps`; a SequenceModel's history records them per epoch, the artefact
their totals. L-BFGS raises ``FloatingPointError`` on a non-finite loss instead. A finite loss can
blow up too (an NLL from -24 to 3e7 in one batch); with ``TrainConfig.restart_on_divergence`` no
step is taken on such a spike, and an epoch whose validation loss blows up restarts from the best
weights.
"""

from __future__ import annotations

import copy
import math
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any, ClassVar

import torch
from torch import Tensor, nn

from fkn_bench.filters import VARIANTS, KalmanFilter, ParameterSet, make_filter
from fkn_bench.limits import check_memory
from fkn_bench.models.registry import DEFAULT_MODEL, make_model, model_names, model_spec
from fkn_bench.runtime import parse_device, resolve_device, torch_threads
from fkn_bench.training.data import Sequences, TrainingData
from fkn_bench.training.objectives import OBJECTIVES, innovation_nll, state_mse

__all__ = ["NoiseModel", "SequenceModel", "DirectParameters", "TrainConfig", "Trainer", "EpochRecord", "OnEpoch"]


class NoiseModel(nn.Module, ABC):
    """Produces unconstrained filter parameters (see module docstring)."""

    parameter_set: ParameterSet

    @abstractmethod
    def window_raw(self, sequences: Sequences) -> Tensor:
        """Unconstrained parameters ``(B, size)`` or ``(B, T, size)`` for a batch of sequences."""

    @abstractmethod
    def deployed_raw(self) -> Tensor:
        """The constant unconstrained parameters ``(size,)`` used after training."""

    @property
    def deploys_network(self) -> bool:
        """True when the trained module itself is deployed (parameters computed along each
        sequence, e.g. FlexKalmanNet's time-varying mode): its artefact then names the weights
        rather than constant parameters. False by default."""
        return False

    def sequence_raw(self, measurements: Tensor, mask: Tensor) -> Tensor:
        """The unconstrained parameters the deployed estimator uses on whole sequences
        ``(B, T, 7)``: :meth:`deployed_raw` unless :attr:`deploys_network`."""
        return self.deployed_raw()


class SequenceModel(nn.Module, ABC):
    """A trained module that brings its own differentiable recursion over a batch of sequences
    (e.g. KalmanNet, whose network computes the gain inside the filter loop) instead of giving
    noise parameters to a filter variant. The :class:`Trainer` calls :meth:`sequence_loss` where it
    would run ``variant.run`` for a :class:`NoiseModel`: the supervised objective, unless the
    model declares others in :attr:`objectives`."""

    objectives: tuple[str, ...] = ("supervised",)
    """The training objectives :meth:`sequence_loss` computes."""

    @abstractmethod
    def sequence_mse(self, sequences: Sequences, *, dt: float, loss_cut: int) -> Tensor:
        """Mean squared state error over steps ``loss_cut:`` of ``sequences`` (a scalar tensor,
        differentiable with respect to the module's parameters)."""

    def sequence_loss(self, sequences: Sequences, *, dt: float, loss_cut: int, objective: str) -> tuple[Tensor, Tensor]:
        """``(objective, 13-state MSE)`` over steps ``loss_cut:`` of ``sequences`` (the same
        tensor for the supervised objective). The default: :meth:`sequence_mse`, supervised only."""
        if objective not in self.objectives:
            raise ValueError(f"{type(self).__name__} trains with the objectives {list(self.objectives)} (got {objective!r})")
        mse = self.sequence_mse(sequences, dt=dt, loss_cut=loss_cut)
        return mse, mse

    @abstractmethod
    def run_means(self, measurements: Tensor, mask: Tensor, *, dt: float) -> Tensor:
        """State estimates ``(B, T, n)`` for measurements ``(B, T, m)`` with validity ``(B, T)``."""

    @abstractmethod
    def describe(self) -> dict[str, Any]:
        """JSON-compatible description of the trained module (the checkpoint's ``deployed`` and
        the artefact's ``parameters``)."""


class DirectParameters(NoiseModel):
    """A learnable unconstrained parameter vector, the same for every sequence: the noise
    parameters themselves are the trainable variables, optimised through the differentiable
    filter (X. Xu and R. Niu (2021), "EKFNet: learning system noise statistics from measurement
    data", ICASSP). With the supervised objective this gives the best constant-parameter filter
    on the training data; with the innovation NLL it is maximum-likelihood noise identification
    without ground truth.

    Args:
        parameter_set: which parameters are learned, and their positivity map.
        initial_std: starting standard deviations by entry (default: the set's fixed values,
            i.e. the paper's manual tuning).
    """

    def __init__(self, parameter_set: ParameterSet, **initial_std: list[float]) -> None:
        super().__init__()
        self.parameter_set = parameter_set
        self.raw = nn.Parameter(parameter_set.initial_values(**initial_std))

    def window_raw(self, sequences: Sequences) -> Tensor:
        return self.raw.expand(sequences.batch_size, -1)

    def deployed_raw(self) -> Tensor:
        return self.raw

    def extra_repr(self) -> str:
        return f"size={self.parameter_set.size}"


@dataclass
class TrainConfig:
    """Data protocol and optimisation settings of a training run (optimisation defaults from the
    paper's table where it has one; the data protocol is the benchmark's, FlexKalmanNet's
    ``DEVIATIONS`` give the measurements behind it).

    Attributes:
        variant: the filter variant trained through (ekf, ukf, mekf).
        process_model: the filter's process model (:func:`fkn_bench.models.model_names`:
            ``constant-velocity``, the paper's; ``rigid-body``; ``rigid-body-ratios``).
        inertia: principal moments (kg m^2) of the rigid-body models: known inertia
            (``rigid-body``; None takes the training scenario's when training starts) or the prior
            mean of the estimated ratios (``rigid-body-ratios``; None: isotropic).
        window, stride, train_measurement_every, episodes: the training windows (see
            :class:`~fkn_bench.training.TrainingData`).
        objective: ``supervised`` (13-state MSE vs truth) or ``nll`` (innovation NLL); a
            subclass may allow others (:attr:`objectives`).
        optimizer: ``adam`` (mini-batches) or ``lbfgs`` (full batch, one step per epoch).
        lbfgs_iterations, lbfgs_history: L-BFGS iterations per epoch and memory.
        epochs: maximum epochs (paper: 100).
        patience: early stopping after this many epochs without a better validation loss (20).
        min_improvement: relative decrease of the validation loss that counts as better
            (1e-4, as ``ReduceLROnPlateau``'s default threshold).
        lr: Adam learning rate (paper: 1e-5).
        weight_decay: Adam weight decay (paper: 0).
        windows_per_batch: windows run in parallel per optimiser step.
        loss_cut: leading steps of every window excluded from the loss (paper: 100).
        seed: seed of initialisation and window order (paper: 0).
        scheduler_factor, scheduler_patience: ``ReduceLROnPlateau`` settings.
        max_grad_norm: gradient-norm clip (None: off).
        restart_on_divergence: a factor ``f`` (None: off, the default). An epoch whose validation
            loss is not finite, or exceeds the best so far by more than ``f`` times the best's
            magnitude (``val - best > f |best|``: twice the best RMSE for ``f = 1``; for an NLL,
            which is negative, a jump by its own size), is a divergence that finite-loss steps
            cannot undo: the weights return to the best epoch's, Adam's moments are cleared and
            the learning rate is multiplied by ``scheduler_factor`` (counted in
            :attr:`Trainer.divergence_restarts`). The same margin guards every Adam batch from
            the second epoch on: a batch whose finite training loss exceeds the last epoch's
            mean training loss by ``f`` times its magnitude is a loss spike, on which no step
            is taken (counted in :attr:`Trainer.loss_spikes`; its loss is left out of the
            epoch's mean), so ``f`` must exceed the spread between one epoch's batches. Unlike
            a non-finite loss it neither undoes the last step nor halves the learning rate:
            the spike is that batch's at weights that hold on the others, and halving at each
            took Cholesky-KalmanNet's learning rate on ds1 from 3e-4 to 1e-11 in 31 epochs
            (45 spikes). Without the option, a learned gain whose training loss jumped to 3e7 in
            one epoch (Cholesky-KalmanNet on ds1) went on from the wrecked weights: only a
            non-finite loss undoes a step.
        threads: torch threads during training.
        device: where the model, the data and the filter run (``cpu``, the default; ``cuda``
            where a GPU exists: :func:`fkn_bench.runtime.resolve_device`). The window order and
            FlexKalmanNet's sample picks are drawn on the CPU either way, so a seed picks the same
            windows on every device; results differ only by the devices' rounding.
    """

    variant: str = "ekf"
    process_model: str = "constant-velocity"
    inertia: tuple[float, float, float] | None = None
    window: int = 800
    stride: int | None = None
    train_measurement_every: int | None = 10
    episodes: int = 4
    objective: str = "supervised"
    optimizer: str = "adam"
    lbfgs_iterations: int = 20
    lbfgs_history: int = 10
    epochs: int = 100
    patience: int = 20
    min_improvement: float = 1e-4
    lr: float = 1e-5
    weight_decay: float = 0.0
    windows_per_batch: int = 64
    loss_cut: int = 100
    seed: int = 0
    scheduler_factor: float = 0.5
    scheduler_patience: int = 5
    max_grad_norm: float | None = None
    restart_on_divergence: float | None = None
    threads: int = 1
    device: str = "cpu"

    objectives: ClassVar[tuple[str, ...]] = OBJECTIVES
    """The values ``objective`` may take (a subclass for a :class:`SequenceModel` with its own)."""

    def __post_init__(self) -> None:
        if self.variant not in VARIANTS:
            raise ValueError(f"variant must be one of {list(VARIANTS)} (got {self.variant!r})")
        if self.process_model not in model_names():
            raise ValueError(f"process_model must be one of {list(model_names())} (got {self.process_model!r})")
        if self.inertia is not None:
            self.inertia = tuple(float(v) for v in self.inertia)  # type: ignore[assignment]
        if not (model_spec(self.process_model).inertia == "required" and self.inertia is None):  # else: the scenario's
            self.build_filter()  # the variant takes the model, and the model its inertia (else ValueError)
        if self.window < 2 or self.loss_cut >= self.window:
            raise ValueError(f"need window >= 2 and loss_cut < window (got {self.window}, {self.loss_cut})")
        if self.objective not in self.objectives:
            raise ValueError(f"objective must be one of {self.objectives} (got {self.objective!r})")
        if self.optimizer not in ("adam", "lbfgs"):
            raise ValueError(f"optimizer must be one of ['adam', 'lbfgs'] (got {self.optimizer!r})")
        for name in ("epochs", "patience", "windows_per_batch", "threads", "lbfgs_iterations", "lbfgs_history"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be >= 1 (got {getattr(self, name)!r})")
        if not (self.lr > 0 and math.isfinite(self.lr)):
            raise ValueError(f"lr must be a finite number > 0 (got {self.lr!r})")
        if self.loss_cut < 0:
            raise ValueError(f"loss_cut must be >= 0 (got {self.loss_cut!r})")
        for name in ("weight_decay", "min_improvement"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"{name} must be a finite number >= 0 (got {getattr(self, name)!r})")
        if not 0 < self.scheduler_factor < 1:
            raise ValueError(f"scheduler_factor must be a number in (0, 1) (got {self.scheduler_factor!r})")
        if self.scheduler_patience < 0:
            raise ValueError(f"scheduler_patience must be >= 0 (got {self.scheduler_patience!r})")
        if self.restart_on_divergence is not None and not (math.isfinite(self.restart_on_divergence)
                                                           and self.restart_on_divergence > 0):
            raise ValueError(f"restart_on_divergence must be None or a finite number > 0 (got {self.restart_on_divergence!r})")
        if self.max_grad_norm is not None and not (math.isfinite(self.max_grad_norm) and self.max_grad_norm > 0):
            raise ValueError(f"max_grad_norm must be a finite number > 0 or none (got {self.max_grad_norm!r})")
        for name in ("stride", "train_measurement_every"):
            if getattr(self, name) is not None and getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1 or none (got {getattr(self, name)!r})")
        parse_device(self.device)  # (whether this machine has it is checked when training starts)

    def to_dict(self) -> dict[str, Any]:
        """The fields; the process model's and the device only when they are not the paper's
        and the CPU (so that the configs of earlier runs, in checkpoints, artefacts and sweep
        studies, read the same)."""
        values = asdict(self)
        if self.device == "cpu":
            del values["device"]
        if self.process_model == DEFAULT_MODEL and self.inertia is None:
            del values["process_model"], values["inertia"]
        elif values["inertia"] is not None:
            values["inertia"] = list(values["inertia"])
        return values

    def build_filter(self, scenario: Any = None) -> KalmanFilter:
        """The filter variant on the process model; a known-inertia model without ``inertia``
        takes ``scenario.inertia``."""
        inertia = self.inertia
        if inertia is None and model_spec(self.process_model).inertia == "required" and scenario is not None:
            inertia = scenario.inertia
        return make_filter(self.variant, model=make_model(self.process_model, inertia=inertia))

    def train_config(self) -> TrainConfig:
        return self


@dataclass
class EpochRecord:
    """One row of the training history."""

    epoch: int
    train_loss: float
    val_loss: float
    val_rmse: float
    lr: float
    seconds: float
    parameters: dict[str, float] = field(default_factory=dict)

    def flat(self) -> dict[str, float]:
        return {**{k: v for k, v in asdict(self).items() if k != "parameters"}, **self.parameters}


OnEpoch = Callable[[int, "list[EpochRecord]"], "bool | None"]
"""``on_epoch(epoch, history)``: called after every epoch (numbered from 1) with the history so far
(its last record is that epoch's: losses, validation RMSE, learning rate, deployed parameters).
Returning True stops the training there (the best epoch's weights are still restored); an
exception it raises (e.g. ``optuna.TrialPruned``) ends the training and propagates."""


TRAINING_BYTES_PER_STEP = 16000
"""Bytes that one step of one training window takes in a forward and backward pass (the autograd
graph of the filter's recursion), for :func:`fkn_bench.limits.check_memory`: a training run of
``W`` windows of ``T`` steps needs about ``W T`` times this (the measured figures per variant:
``fkn_bench/DESIGN.md``, "Performance notes")."""


class Trainer:
    """Trains a :class:`NoiseModel` through ``variant`` (or a :class:`SequenceModel` through its
    own recursion) on ``data`` (see module docstring), on ``config.device``: the model and the
    data are moved there."""

    def __init__(self, model: NoiseModel | SequenceModel, variant: KalmanFilter, data: TrainingData, config: TrainConfig) -> None:
        if config.loss_cut >= data.window:
            raise ValueError(f"loss_cut ({config.loss_cut}) must be smaller than the window ({data.window})")
        self.device = resolve_device(config.device)
        model.to(self.device)
        move = getattr(data, "to", None)  # (a duck-typed data set without it stays where it is)
        self.model, self.variant, self.config = model, variant, config
        self.data = move(self.device) if move is not None else data
        total = data.train.batch_size  # (duck-typed data: the training sequences are all we rely on)
        windows = total if config.optimizer == "lbfgs" else min(config.windows_per_batch, total)
        check_memory(windows * data.window * TRAINING_BYTES_PER_STEP,
                     f"training on batches of {windows} window(s) of {data.window} steps ({config.optimizer})",
                     "fewer windows per batch (windows_per_batch) or shorter windows (window)")
        if config.optimizer == "lbfgs":
            self.optimizer: torch.optim.Optimizer = torch.optim.LBFGS(
                model.parameters(), lr=config.lr, max_iter=config.lbfgs_iterations, history_size=config.lbfgs_history,
                line_search_fn="strong_wolfe", tolerance_grad=1e-10, tolerance_change=1e-12,
            )
        else:
            self.optimizer = torch.optim.Adam(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
        self.scheduler = torch.optim.lr_scheduler.ReduceLROnPlateau(
            self.optimizer, mode="min", factor=config.scheduler_factor, patience=config.scheduler_patience
        )
        self.generator = torch.Generator().manual_seed(config.seed)
        self.history: list[EpochRecord] = []
        self.best_loss = math.inf
        self.best_epoch = 0
        self.best_state: dict[str, Tensor] = copy.deepcopy(model.state_dict())
        self.epochs_without_improvement = 0
        self.evaluations = 0  # loss evaluations of the L-BFGS steps
        self.divergence_restarts = 0  # epochs restarted from the best weights (TrainConfig.restart_on_divergence)
        self.loss_spikes = 0  # finite training losses past the divergence margin (TrainConfig.restart_on_divergence)
        # Adam steps taken, of them with the gradient norm clipped (counted when max_grad_norm is
        # set), batches skipped for a non-finite loss or gradient, and steps undone for one
        self.gradient_steps = {"taken": 0, "clipped": 0, "skipped_nonfinite": 0, "rolled_back": 0}
        self._before_step: tuple[dict[str, Any], dict[str, Any]] | None = None  # (model, optimiser) states

    # ------------------------------------------------------------------ losses
    def loss(self, sequences: Sequences, raw: Tensor | None) -> tuple[Tensor, Tensor]:
        """Objective on ``sequences`` with parameters ``raw``, and the 13-state MSE (the same
        tensor for the supervised objective; a diagnostic for ``nll``). A :class:`SequenceModel`
        runs its own recursion (``raw`` is None)."""
        if isinstance(self.model, SequenceModel):
            return self.model.sequence_loss(sequences, dt=self.data.scenario.dt, loss_cut=self.config.loss_cut,
                                            objective=self.config.objective)
        noise = self.model.parameter_set.to_noise(raw)
        nll = self.config.objective == "nll"
        result = self.variant.run(noise, sequences.measurements, sequences.mask, dt=self.data.scenario.dt,
                                  store_covariances=False, store_innovations=nll)
        mse = state_mse(result.means, sequences.truth, self.config.loss_cut)
        if nll:
            return innovation_nll(result, self.config.loss_cut), mse
        return mse, mse

    def _reported(self, loss: float) -> float:
        """A loss as reported: the RMSE for the supervised objective (its loss is the MSE)."""
        return math.sqrt(loss) if self.config.objective == "supervised" else loss

    def validate(self) -> tuple[float, float]:
        """``(validation loss, validation 13-state RMSE)`` with the deployed parameters; the loss
        (square root of the MSE, or the NLL) selects the best epoch."""
        with torch.no_grad():
            own = isinstance(self.model, SequenceModel)
            raw = None if own else self.model.deployed_raw().expand(self.data.val.batch_size, -1)
            loss, mse = self.loss(self.data.val, raw)
        return self._reported(float(loss)), math.sqrt(float(mse))

    # ------------------------------------------------------------------ epochs
    def _window_raw(self, batch: Sequences) -> Tensor | None:
        return None if isinstance(self.model, SequenceModel) else self.model.window_raw(batch)

    def _backward(self, batch: Sequences, *, raise_nonfinite: bool = True) -> Tensor:
        """The training loss on ``batch``, its gradients computed when it is finite; a non-finite
        loss raises FloatingPointError (or, with ``raise_nonfinite=False``, is returned as is)."""
        self.optimizer.zero_grad(set_to_none=True)
        loss = self.loss(batch, self._window_raw(batch))[0]
        if not torch.isfinite(loss):
            if raise_nonfinite:
                raise FloatingPointError(f"non-finite training loss at epoch {len(self.history) + 1}: lower the learning rate")
            return loss
        loss.backward()
        return loss

    def _gradient_norm(self) -> float:
        """The gradients' total norm, clipped to ``max_grad_norm`` when set (counted)."""
        limit = self.config.max_grad_norm
        if limit is None:
            return float(nn.utils.get_total_norm([p.grad for p in self.model.parameters() if p.grad is not None]))
        norm = float(nn.utils.clip_grad_norm_(self.model.parameters(), limit))
        self.gradient_steps["clipped"] += math.isfinite(norm) and norm > limit
        return norm

    def _undo_last_step(self) -> None:
        """Return the weights and the optimiser's state to before the last step and halve the
        learning rate; without a step to undo, count the batch as skipped (module docstring)."""
        if self._before_step is None:
            self.gradient_steps["skipped_nonfinite"] += 1
            return
        model_state, optimizer_state = self._before_step
        self.model.load_state_dict(model_state)
        self.optimizer.load_state_dict(optimizer_state)
        for group in self.optimizer.param_groups:
            group["lr"] *= 0.5
        self._before_step = None
        self.gradient_steps["rolled_back"] += 1

    def _lbfgs_epoch(self) -> float:
        batch = self.data.train

        def closure() -> Tensor:
            loss = self._backward(batch)
            self.evaluations += 1
            return loss

        self.model.train()
        start = self.optimizer.step(closure)  # type: ignore[arg-type]
        self.model.eval()
        with torch.no_grad():  # the loss at the parameters the step ended with
            end, _ = self.loss(batch, self._window_raw(batch))
        return self._reported(float(end if torch.isfinite(end) else start))

    def run_epoch(self) -> float:
        """One epoch (see module docstring); returns the mean training loss (the 13-state RMSE for
        the supervised objective, the NLL otherwise)."""
        if self.config.optimizer == "lbfgs":
            return self._lbfgs_epoch()
        self.model.train()
        total, count, undone, spikes = 0.0, 0, self.gradient_steps["rolled_back"], self.loss_spikes
        for batch in self.data.batches(self.config.windows_per_batch, self.generator):
            loss = self._backward(batch, raise_nonfinite=False)
            if torch.isfinite(loss) and self._spiked(self._reported(float(loss.detach()))):  # no step on a spike
                self.loss_spikes += 1
                continue
            if torch.isfinite(loss):
                total += float(loss.detach()) * batch.batch_size
                count += batch.batch_size
            if not (torch.isfinite(loss) and math.isfinite(self._gradient_norm())):
                self._undo_last_step()  # no step from here; undo the one that led here, if any
                continue
            self._before_step = (copy.deepcopy(self.model.state_dict()), copy.deepcopy(self.optimizer.state_dict()))
            self.optimizer.step()
            self.gradient_steps["taken"] += 1
        self.model.eval()
        if not count and self.gradient_steps["rolled_back"] == undone and self.loss_spikes == spikes:
            # nothing to learn from, nothing undone, no spike (an epoch of spikes is a divergence: inf)
            raise FloatingPointError(f"no finite training loss in epoch {len(self.history) + 1}: the filter "
                                     "diverges at the starting weights on every batch")
        return self._reported(total / count) if count else math.inf

    def _past_margin(self, loss: float, reference: float) -> bool:
        """Whether ``loss`` is past ``restart_on_divergence``'s margin above ``reference``
        (:class:`TrainConfig`): not finite, or ``loss - reference > f |reference|``; never while
        the option is off or there is no finite reference yet."""
        factor = self.config.restart_on_divergence
        if factor is None or not math.isfinite(reference):
            return False
        return not math.isfinite(loss) or loss - reference > factor * abs(reference)

    def _diverged(self, val_loss: float) -> bool:
        """Whether ``val_loss`` is a divergence: past the margin above the best so far."""
        return self._past_margin(val_loss, self.best_loss)

    def _spiked(self, train_loss: float) -> bool:
        """Whether a batch's ``train_loss`` is a spike: past the margin above the last epoch's
        mean training loss."""
        return self._past_margin(train_loss, self.history[-1].train_loss if self.history else math.inf)

    def _restart_from_best(self) -> None:
        """Back to the best epoch's weights, with fresh Adam moments and a lower learning rate."""
        self.model.load_state_dict(self.best_state)
        self.optimizer.state.clear()
        for group in self.optimizer.param_groups:
            group["lr"] *= self.config.scheduler_factor
        self._before_step = None
        self.divergence_restarts += 1

    def deployed_parameters(self) -> dict[str, float]:
        """The deployed standard deviations by name (e.g. ``sigma_Q_qw``); for a
        :class:`SequenceModel`, the gradient-step counts so far (steps taken, clipped, skipped)."""
        if isinstance(self.model, SequenceModel):
            return {f"gradient_steps_{k}": float(v) for k, v in self.gradient_steps.items()}
        with torch.no_grad():
            raw = self.model.deployed_raw()
        entries = self.model.parameter_set.to_dict(raw)["entries"]
        return {f"sigma_{name.split('_')[0].upper()}_{label}": float(v) for name, entry in entries.items()
                if "std" in entry for label, v in zip(entry["labels"], entry["std"])}

    def fit(self, *, on_epoch: OnEpoch | None = None, progress: bool = True) -> list[EpochRecord]:
        """Train until ``epochs``, early stopping or ``on_epoch`` (:data:`OnEpoch`) asks to stop;
        restores the best weights. A trainer restored with :meth:`load_state_dict` resumes."""
        from tqdm.auto import tqdm

        start = len(self.history) + 1
        bar = tqdm(
            range(start, self.config.epochs + 1), desc="train", unit="epoch", disable=not progress, leave=False,
            initial=start - 1, total=self.config.epochs,
        )
        with torch_threads(self.config.threads):
            for epoch in bar:
                began = time.perf_counter()
                train_loss = self.run_epoch()
                val_loss, val_rmse = self.validate()
                self.scheduler.step(val_loss)
                record = EpochRecord(epoch, train_loss, val_loss, val_rmse, self.optimizer.param_groups[0]["lr"],
                                     time.perf_counter() - began, self.deployed_parameters())
                self.history.append(record)
                margin = self.config.min_improvement * abs(self.best_loss) if math.isfinite(self.best_loss) else 0.0
                if self._diverged(val_loss):  # no better, and trained on from the best weights
                    self._restart_from_best()
                    self.epochs_without_improvement += 1
                elif val_loss < self.best_loss - margin:
                    self.best_loss, self.best_epoch = val_loss, epoch
                    self.best_state = copy.deepcopy(self.model.state_dict())
                    self.epochs_without_improvement = 0
                else:
                    self.epochs_without_improvement += 1
                bar.set_postfix(train=f"{train_loss:.4g}", val=f"{val_loss:.4g}", lr=f"{record.lr:.1e}", best=self.best_epoch)
                stop = on_epoch is not None and on_epoch(epoch, self.history)
                if stop or self.epochs_without_improvement >= self.config.patience:
                    break
        bar.close()
        self.model.load_state_dict(self.best_state)
        return self.history

    # ------------------------------------------------------------------ resume
    _MODULES = ("model", "optimizer", "scheduler")
    _VALUES = ("best_loss", "best_epoch", "best_state", "epochs_without_improvement", "evaluations", "divergence_restarts",
               "loss_spikes")

    def _generators(self) -> dict[str, torch.Generator]:
        """Every random generator the training draws from, by name: the window order's
        (``generator``), the model's own (a :class:`torch.Generator` attribute of any submodule,
        e.g. FlexKalmanNet's sample picks: ``model.<submodule>.<attribute>``) and torch's default
        generators (``torch``: dropout on the CPU; ``cuda``: on the GPU, when training there)."""
        found = {"generator": self.generator, "torch": torch.default_generator}
        for prefix, module in self.model.named_modules():
            for attribute, value in vars(module).items():
                if isinstance(value, torch.Generator):
                    found[".".join(filter(None, ("model", prefix, attribute)))] = value
        if self.device.type == "cuda":
            index = self.device.index if self.device.index is not None else torch.cuda.current_device()
            found["cuda"] = torch.cuda.default_generators[index]
        return found

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to resume exactly: model, optimiser, scheduler, the states of every
        random generator (:meth:`_generators`; numpy's and Python's are not used), history, best
        epoch, counts, and the weights and optimiser state before the last step (a non-finite first
        batch of the next epoch undoes that step, module docstring). A trainer that loads it
        continues as the uninterrupted one would, bit for bit on the same machine."""
        return {
            **{name: getattr(self, name).state_dict() for name in self._MODULES},
            "generator": self.generator.get_state(),
            "generators": {name: generator.get_state() for name, generator in self._generators().items()},
            "before_step": None if self._before_step is None else {"model": self._before_step[0],
                                                                    "optimizer": self._before_step[1]},
            "history": [asdict(r) for r in self.history],
            "gradient_steps": dict(self.gradient_steps),
            **{name: getattr(self, name) for name in self._VALUES},
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` (one written before the generators' and the last step's
        states were recorded restores the window order's generator only)."""
        for name in self._MODULES:
            getattr(self, name).load_state_dict(state[name])
        self.generator.set_state(state["generator"])
        generators = self._generators()
        for name, generator_state in state.get("generators", {}).items():
            if name in generators:
                generators[name].set_state(generator_state)
        before = state.get("before_step")
        self._before_step = None if before is None else (before["model"], before["optimizer"])
        self.history = [EpochRecord(**r) for r in state["history"]]
        self.gradient_steps.update(state.get("gradient_steps", {}))
        for name in self._VALUES:
            if name in state:
                setattr(self, name, state[name])
