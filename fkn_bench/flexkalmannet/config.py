"""FlexKalmanNet's configuration: architecture, what is learned, data windows, optimisation.

Defaults follow the paper's Table I (input 7, output 20, hidden 512, 7 layers, LeakyReLU, Adam,
ReduceLROnPlateau, MSE loss, loss cut 100, 100 epochs, early stopping after 20, seed 0, no
dropout or weight decay) except where measured otherwise; every deviation is listed in
:data:`DEVIATIONS` with the measurement behind it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fkn_bench.filters.parameters import LEARNABLE_ENTRIES
from fkn_bench.training import TrainConfig
from fkn_bench.training.options import check_option_types, naming_the_file
from fkn_bench.training.pipeline import options_with_file

__all__ = ["FlexKalmanNetConfig", "DEVIATIONS", "PAPER_TABLE"]

PAPER_TABLE: dict[str, Any] = {
    "seed": 0,
    "input_size": 7,
    "output_size": 20,
    "batch_size": 512,
    "hidden": 512,
    "layers": 7,
    "lr": 1e-5,
    "dropout": 0.0,
    "weight_decay": 0.0,
    "loss": "MSE",
    "scheduler": "ReduceLROnPlateau",
    "loss_cut": 100,
    "optimizer": "Adam",
    "activation": "LeakyReLU",
    "epochs": 100,
    "patience": 20,
}
"""The paper's Table I ("best found common hyperparameter set"), quoted."""

DEVIATIONS: dict[str, str] = {
    "window": (
        "800 consecutive samples per window instead of the paper's batch of 512. Test 13-state "
        "RMSE on ds1 (20 seeds, measurements every 10 steps, scored from step 100): 512 -> 0.0131, "
        "1600 -> 0.0127 with one episode; 1600 -> 0.0118 and 800 -> 0.0118 with four. Longer "
        "windows weigh the filter's steady state (what evaluation scores) more than its start-up; "
        "800 matches 1600 at half the sequential depth, so epochs are faster."
    ),
    "train_measurement_every": (
        "10, as in evaluation, instead of a measurement every step: 0.01308 vs 0.01309 (512-sample "
        "windows, one episode), equal, and nine of ten steps are cheap predictions."
    ),
    "episodes": (
        "Four recordings (seeds 0-3) instead of the paper's one: the 20 parameters fitted to one "
        "noise realisation generalise worse (test 0.0127 vs 0.0118; angular-rate RMSE 0.0026 vs "
        "0.0018 rad/s). The simulator can record more, a real test campaign could too."
    ),
    "lr": (
        "5e-4 instead of 1e-5. All windows run through the filter in one batch, so an epoch is "
        "one optimiser step (the paper: 25); at 1e-5 the parameters barely leave the manual tuning "
        "in 100 epochs, at 1e-3 Adam overshoots and early stopping ends at a worse point (0.0132), "
        "3e-4 reaches the same 0.0118 in more epochs."
    ),
    "windows_per_batch": "64: every window of an epoch in one batch (the filter runs them in parallel).",
    "samples_per_window": (
        "16 measurements per window feed the network (their outputs' mean is the window's "
        "parameters); the network costs 1/32 of all 512, its output varies little across samples."
    ),
    "scheduler": "ReduceLROnPlateau with factor 0.5 and patience 8 (the paper does not give them).",
}
"""Defaults that differ from the paper's table, and why (the measurements behind each: train with
``fkn-bench train --estimator flexkalmannet --scenario ds1 --set KEY=VALUE --out DIR``, score
with ``fkn-bench run --estimator flexkalmannet --estimator-option parameters=DIR/parameters.json
--scenario ds1 --seeds 20``)."""


_MODEL_FIELDS = ("learn", "positivity", "hidden", "layers", "activation", "dropout", "network_dtype", "output_scale",
                 "mode", "samples_per_window", "history")
_NOT_OPTIONS = ("optimizer", "lbfgs_iterations", "lbfgs_history")  # FlexKalmanNet trains with Adam


@dataclass
class FlexKalmanNetConfig(TrainConfig):
    """Everything that defines a FlexKalmanNet training run (flat, for TOML files and sweeps).

    Model: ``variant`` (ekf, ukf, mekf), ``learn`` (entries of the parameter set, default the
    paper's 20 standard deviations), ``positivity``, ``hidden``, ``layers``, ``activation``,
    ``dropout``, ``network_dtype``, ``mode`` (constant or time_varying), ``samples_per_window``,
    ``history``. The data and optimisation fields are :class:`~fkn_bench.training.TrainConfig`'s
    (the benchmark's protocol, shared with the tuned baselines) with FlexKalmanNet's ``lr`` and
    ``scheduler_patience``; it trains with Adam (``optimizer`` and the L-BFGS settings are not
    among its options: :meth:`to_dict` lists the options).
    """

    learn: tuple[str, ...] | str = ("q_std", "r_std")  # (a str: "q_std,r_std", a sweep's categorical value)
    positivity: str = "log"
    hidden: int = 512
    layers: int = 7
    activation: str = "leaky_relu"
    dropout: float = 0.0
    network_dtype: str = "float32"
    output_scale: float = 1e-3
    mode: str = "constant"
    samples_per_window: int | None = 16
    history: int = 50
    lr: float = 5e-4
    scheduler_patience: int = 8

    def __post_init__(self) -> None:
        if isinstance(self.learn, str):  # "q_std,r_std" (a sweep's categorical value)
            self.learn = tuple(part.strip() for part in self.learn.split(",") if part.strip())
        self.learn = tuple(self.learn)
        bad = [e for e in self.learn if e not in LEARNABLE_ENTRIES]
        if bad:
            raise ValueError(f"learn: unknown entries {bad}; valid: {list(LEARNABLE_ENTRIES)}")
        if self.mode not in ("constant", "time_varying"):
            raise ValueError(f"mode must be 'constant' or 'time_varying' (got {self.mode!r})")
        if self.network_dtype not in ("float32", "float64"):
            raise ValueError(f"network_dtype must be 'float32' or 'float64' (got {self.network_dtype!r})")
        if self.samples_per_window is not None and self.samples_per_window < 1:
            raise ValueError(f"samples_per_window must be >= 1 or None (got {self.samples_per_window})")
        for name in ("hidden", "layers", "history"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1 (got {getattr(self, name)!r})")
        if not 0.0 <= self.dropout < 1.0:
            raise ValueError(f"dropout must be a number in [0, 1) (got {self.dropout!r})")
        if not (math.isfinite(self.output_scale) and self.output_scale > 0):
            raise ValueError(f"output_scale must be a finite number > 0 (got {self.output_scale!r})")
        super().__post_init__()  # the variant, data protocol and optimisation fields

    def to_dict(self) -> dict[str, Any]:
        """The options: the variant, the model fields, then the data and optimisation fields."""
        values = {k: v for k, v in super().to_dict().items() if k not in _NOT_OPTIONS}
        values["learn"] = list(self.learn)
        return {**{k: values.pop(k) for k in ("variant", *_MODEL_FIELDS)}, **values}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> FlexKalmanNetConfig:
        known = {f.name for f in dataclasses.fields(cls)} - set(_NOT_OPTIONS)
        unknown = sorted(set(data) - known)
        if unknown:
            files = sorted({source for key, source in getattr(data, "sources", {}).items() if key in unknown})
            raise ValueError("".join(f"{f}: " for f in files) + f"unknown FlexKalmanNet config keys {unknown}; "
                             f"valid: {sorted(known)}")
        check_option_types(cls, data, "FlexKalmanNet")
        try:
            return cls(**dict(data))
        except ValueError as exc:  # a value out of range: name its file, when it came from one
            raise naming_the_file(exc, data) from None

    @classmethod
    def from_toml(cls, path: str | Path) -> FlexKalmanNetConfig:
        """Read a TOML file whose top level (or ``[flexkalmannet]`` table) holds config keys."""
        return cls.from_options({"config": str(path)})

    @classmethod
    def from_options(cls, options: Mapping[str, Any]) -> FlexKalmanNetConfig:
        """The defaults, then the TOML file named by option ``config``, then the other options."""
        return cls.from_dict(options_with_file(options, "flexkalmannet"))

    def replace(self, **changes: Any) -> FlexKalmanNetConfig:
        return dataclasses.replace(self, **changes)
