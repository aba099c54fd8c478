"""Training filter parameters through the filter recursion (shared by FlexKalmanNet and the
tuned baselines)."""

from fkn_bench.training.data import Sequences, TrainingData
from fkn_bench.training.direct import DirectParameters
from fkn_bench.training.objectives import OBJECTIVES, innovation_nll, state_mse
from fkn_bench.training.trainer import EpochRecord, NoiseModel, TrainConfig, Trainer

__all__ = [
    "OBJECTIVES",
    "DirectParameters",
    "EpochRecord",
    "NoiseModel",
    "Sequences",
    "TrainConfig",
    "Trainer",
    "TrainingData",
    "innovation_nll",
    "state_mse",
]
