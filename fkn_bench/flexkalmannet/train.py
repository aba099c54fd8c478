"""Train FlexKalmanNet: the shared pipeline (:func:`fkn_bench.training.fit`) with FlexKalmanNet's
declaration (:data:`TRAINABLE`: its config and model), writing checkpoint, history, figures and
the learned-parameter artefact (see :mod:`fkn_bench.training.pipeline`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fkn_bench.flexkalmannet.checkpoint import build_model
from fkn_bench.flexkalmannet.config import FlexKalmanNetConfig
from fkn_bench.scenarios import Scenario
from fkn_bench.training import Trainable, TrainingOutcome, fit

__all__ = ["TRAINABLE", "train_flexkalmannet"]

TRAINABLE = Trainable(config=FlexKalmanNetConfig.from_options, build=build_model)
"""FlexKalmanNet's training declaration (its registry entry's ``trainable``)."""


def train_flexkalmannet(
    scenario: str | Scenario = "ds1", config: FlexKalmanNetConfig | None = None, *, out: str | Path, **options: Any
) -> TrainingOutcome:
    """:func:`~fkn_bench.training.fit` of ``flexkalmannet`` (``options``: ``resume``, ``progress``,
    ``plots``, ``on_epoch``)."""
    return fit("flexkalmannet", scenario, config, out=out, **options)
