"""KalmanNet's training configuration: architecture, data windows, optimisation.

The data protocol and optimisation fields are :class:`~fkn_bench.training.TrainConfig`'s (the
benchmark's protocol, shared with FlexKalmanNet and the tuned EKFs); KalmanNet adds the network's
fields and changes a few defaults (below). It trains with Adam on the supervised objective (the
paper's MSE against the true state, its training algorithm), so ``variant``, ``objective``, ``optimizer``
and the L-BFGS settings are not among its options. The other learned-gain filters' configs extend it:
:class:`RecursiveKalmanNetConfig`, :class:`SplitKalmanNetConfig` and :class:`CholeskyKalmanNetConfig`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Self

from fkn_bench.training import TrainConfig
from fkn_bench.training.options import check_option_types, naming_the_file
from fkn_bench.training.pipeline import options_with_file

__all__ = ["CholeskyKalmanNetConfig", "KalmanNetConfig", "RecursiveKalmanNetConfig", "SplitKalmanNetConfig"]

_MODEL_FIELDS = ("manifold", "in_mult", "out_mult", "network_dtype", "detach_every", "initial_gain", "output_scale")
_NOT_OPTIONS = ("variant", "objective", "optimizer", "lbfgs_iterations", "lbfgs_history")


@dataclass
class KalmanNetConfig(TrainConfig):
    """Everything that defines a KalmanNet training run (flat, for TOML files and sweeps).

    Model: ``manifold`` (``auto``: the pose tangent space on the pose model), ``in_mult`` and
    ``out_mult`` (the paper's input and output multipliers; the authors' code uses 5 and 40; on
    the pose model 40 gives 2.1 million weights, 1.4 million of them in FC2's hidden layer, and
    the default 10 gives 0.78 million), ``network_dtype``, ``detach_every`` (truncated
    back-propagation through time: the recurrent state is detached every this many time steps of
    a training window; None: never), ``initial_gain`` and ``output_scale`` (the gain network
    starts near ``initial_gain`` times the gain that moves the observed states onto the
    measurement, FC2's output weights scaled by ``output_scale``; a deviation from the paper,
    whose default initialisation diverged on ds1 from the first window: 13-state RMSE 1e52,
    every gradient non-finite; None and 1.0 restore it).
    Changed defaults of the shared fields: ``lr`` 1e-3 (Adam), ``max_grad_norm`` 1.0 (gradient
    clipping; how often it engaged is recorded per epoch), ``windows_per_batch`` 16 (four Adam
    steps per epoch on the default 64 windows of 800 steps), ``detach_every`` 400 (two chunks of a
    window), ``patience`` 30 and ``scheduler_patience`` 10 (with four steps an epoch the validation
    RMSE swings by 10-20% from one epoch to the next; with the shared 20 and 5, a ds1 seed whose
    best epoch came early stopped at epoch 33 at 0.0217, 36% above the best of ten seeds, and with
    30 and 10 it reached 0.0185; the ten-seed study is the sweep space ``kalmannet-seeds``).
    """

    manifold: str = "auto"
    in_mult: int = 5
    out_mult: int = 10
    network_dtype: str = "float32"
    detach_every: int | None = 400
    initial_gain: float | None = 0.5
    output_scale: float = 0.1
    lr: float = 1e-3
    max_grad_norm: float | None = 1.0
    windows_per_batch: int = 16
    patience: int = 30
    scheduler_patience: int = 10

    objectives: ClassVar[tuple[str, ...]] = ("supervised",)
    _label: ClassVar[str] = "KalmanNet"
    _table: ClassVar[str] = "kalmannet"  # the TOML table of its options
    _model_fields: ClassVar[tuple[str, ...]] = _MODEL_FIELDS
    _not_options: ClassVar[tuple[str, ...]] = _NOT_OPTIONS

    def __post_init__(self) -> None:
        if self.manifold not in ("auto", "pose-tangent", "euclidean"):
            raise ValueError(f"manifold must be 'auto', 'pose-tangent' or 'euclidean' (got {self.manifold!r})")
        if self.network_dtype not in ("float32", "float64"):
            raise ValueError(f"network_dtype must be 'float32' or 'float64' (got {self.network_dtype!r})")
        for name in ("in_mult", "out_mult"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be >= 1 (got {getattr(self, name)!r})")
        if self.detach_every is not None and self.detach_every < 1:
            raise ValueError(f"detach_every must be >= 1 or None (got {self.detach_every!r})")
        if self.objective not in self.objectives or self.optimizer != "adam":
            raise ValueError(f"{self._label} trains with Adam on the {' or '.join(self.objectives)} objective")
        super().__post_init__()

    def to_dict(self) -> dict[str, Any]:
        """The options: the model fields, then the data and optimisation fields."""
        values = {k: v for k, v in super().to_dict().items() if k not in self._not_options}
        return {**{k: values.pop(k) for k in self._model_fields}, **values}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Self:
        known = {f.name for f in dataclasses.fields(cls)} - set(cls._not_options)
        unknown = sorted(set(data) - known)
        if unknown:
            files = sorted({source for key, source in getattr(data, "sources", {}).items() if key in unknown})
            raise ValueError("".join(f"{f}: " for f in files) + f"unknown {cls._label} config keys {unknown}; "
                             f"valid: {sorted(known)}")
        check_option_types(cls, data, cls._label)
        try:
            return cls(**dict(data))
        except ValueError as exc:  # a value out of range: name its file, when it came from one
            raise naming_the_file(exc, data) from None

    @classmethod
    def from_toml(cls, path: str | Path) -> Self:
        """Read a TOML file whose top level (or ``[kalmannet]`` table; ``[recursive-kalmannet]``,
        ``[split-kalmannet]``, ``[cholesky-kalmannet]`` for the other configs) holds config keys."""
        return cls.from_options({"config": str(path)})

    @classmethod
    def from_options(cls, options: Mapping[str, Any]) -> Self:
        """The defaults, then the TOML file named by option ``config``, then the other options."""
        return cls.from_dict(options_with_file(options, cls._table))

    def replace(self, **changes: Any) -> Self:
        return dataclasses.replace(self, **changes)


@dataclass
class RecursiveKalmanNetConfig(KalmanNetConfig):
    """Everything that defines a Recursive KalmanNet training run (Mortada, Falcon, Kahil,
    Clavaud & Michel, "Recursive KalmanNet: Deep Learning-Augmented Kalman Filtering for State
    Estimation with Consistent Uncertainty Quantification", EUSIPCO 2025; flat, for TOML files
    and sweeps; TOML table ``[recursive-kalmannet]``).

    KalmanNet's fields, read for its two recurrent branches (each ``FC-in -> GRU -> FC-out ->
    linear``, :class:`~fkn_bench.kalmannet.recursive.GRUBranch`): ``in_mult`` (FC-in width per
    input), ``hidden_mult`` (GRU hidden size per output), ``out_mult`` (FC-out width per hidden
    unit; the paper's code uses 10, 10 and 20: 30 million weights on the pose model, and the
    defaults 5, 2 and 2 give 0.45 million), ``initial_gain`` and ``output_scale`` (the gain branch
    starts near ``initial_gain`` times the observed gain, as KalmanNet's; both branches' output
    weights scaled by ``output_scale``). Added:

    * ``objective``: ``gaussian-nll`` (the paper's loss: the Gaussian negative log-likelihood of
      the true state under the estimate and its covariance, every step after ``loss_cut``) or
      ``supervised`` (the 13-state MSE, KalmanNet's; the covariance branch then gets no gradient);
    * ``initial_std``: the standard deviation (tangent units: rad, m, rad/s, m/s) on the diagonal
      of the covariance branch's Cholesky factor at initialisation;
    * ``std_floor``: ``std_floor^2 I`` is added to every posterior covariance (positive definite
      by construction, however the network's factor degenerates);
    * ``process_std``: the starting value of a learned diagonal process noise (per tangent
      component, unit per square root of a second) added to the covariance over the prediction
      steps between measurements (None: none, the paper's ``F P F^T``; see the deviations in
      :mod:`fkn_bench.kalmannet.recursive`).
    """

    hidden_mult: int = 2
    out_mult: int = 2
    initial_std: float = 0.01
    std_floor: float = 1e-4
    process_std: float | None = 1e-3
    objective: str = "gaussian-nll"
    patience: int = 20  # the shared defaults: its ds1 and ds2 runs improved to their last epoch
    scheduler_patience: int = 5

    objectives: ClassVar[tuple[str, ...]] = ("gaussian-nll", "supervised")
    _label: ClassVar[str] = "Recursive KalmanNet"
    _table: ClassVar[str] = "recursive-kalmannet"
    _model_fields: ClassVar[tuple[str, ...]] = (
        "manifold", "in_mult", "hidden_mult", "out_mult", "network_dtype", "detach_every", "initial_gain", "output_scale",
        "initial_std", "std_floor", "process_std",
    )
    _not_options: ClassVar[tuple[str, ...]] = ("variant", "optimizer", "lbfgs_iterations", "lbfgs_history")

    def __post_init__(self) -> None:
        if int(self.hidden_mult) < 1:
            raise ValueError(f"hidden_mult must be >= 1 (got {self.hidden_mult!r})")
        if not (self.initial_std > 0 and self.std_floor > 0 and self.initial_std > self.std_floor):
            raise ValueError(f"need initial_std > std_floor > 0 (got {self.initial_std!r}, {self.std_floor!r})")
        if self.process_std is not None and not self.process_std > 0:
            raise ValueError(f"process_std must be > 0 or None (got {self.process_std!r})")
        super().__post_init__()


@dataclass
class SplitKalmanNetConfig(KalmanNetConfig):
    """Everything that defines a Split-KalmanNet training run (Choi, Park, Shlezinger, Eldar &
    Lee, "Split-KalmanNet: A Robust Model-Based Deep Learning Approach for State Estimation", IEEE
    Trans. Vehicular Technology 2023; flat, for TOML files and sweeps; TOML table
    ``[split-kalmannet]``).

    KalmanNet's fields, read for the two recurrent branches (state and measurement, each ``FC-in
    -> GRU -> FC-out -> linear``, :class:`~fkn_bench.kalmannet.recursive.GRUBranch`): ``in_mult``,
    ``hidden_mult`` (GRU hidden size per output), ``out_mult``; ``initial_gain`` (``g > 0``: the
    branches' zero outputs are the reference covariances, whose gain is ``g`` times the observed
    gain; a number, not None) and ``output_scale`` (both branches' output weights). Added:
    ``std_floor`` (``std_floor^2 I`` added to every reported posterior covariance). Trained on the
    supervised objective (the paper's MSE), so ``objective`` is not among its options.
    """

    hidden_mult: int = 2
    out_mult: int = 2
    std_floor: float = 1e-4
    patience: int = 20  # the shared defaults (Recursive KalmanNet's)
    scheduler_patience: int = 5

    _label: ClassVar[str] = "Split-KalmanNet"
    _table: ClassVar[str] = "split-kalmannet"
    _model_fields: ClassVar[tuple[str, ...]] = (
        "manifold", "in_mult", "hidden_mult", "out_mult", "network_dtype", "detach_every", "initial_gain", "output_scale",
        "std_floor",
    )

    def __post_init__(self) -> None:
        if int(self.hidden_mult) < 1:
            raise ValueError(f"hidden_mult must be >= 1 (got {self.hidden_mult!r})")
        if self.initial_gain is None or not self.initial_gain > 0:
            raise ValueError(f"{self._label} needs initial_gain > 0 (got {self.initial_gain!r})")
        if not self.std_floor > 0:
            raise ValueError(f"std_floor must be > 0 (got {self.std_floor!r})")
        super().__post_init__()


@dataclass
class CholeskyKalmanNetConfig(SplitKalmanNetConfig):
    """Everything that defines a Cholesky-KalmanNet training run (Ko & Shafieezadeh,
    "Cholesky-KalmanNet: Model-Based Deep Learning with Positive Definite Error Covariance
    Structure", IEEE Signal Processing Letters 2025; TOML table ``[cholesky-kalmannet]``):
    Split-KalmanNet's fields, and ``objective``: ``gaussian-nll`` (the Gaussian negative
    log-likelihood of the true state under the estimate and its posterior covariance, every step
    after ``loss_cut``; see :mod:`fkn_bench.kalmannet.cholesky` for the reference code's loss) or
    ``supervised`` (the MSE)."""

    objective: str = "gaussian-nll"

    objectives: ClassVar[tuple[str, ...]] = ("gaussian-nll", "supervised")
    _label: ClassVar[str] = "Cholesky-KalmanNet"
    _table: ClassVar[str] = "cholesky-kalmannet"
    _not_options: ClassVar[tuple[str, ...]] = ("variant", "optimizer", "lbfgs_iterations", "lbfgs_history")
