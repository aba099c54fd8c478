"""Training filter parameters through the filter recursion: one pipeline (:func:`fit`) for every
trainable estimator (FlexKalmanNet, the tuned baselines, the sweep's trials)."""

from fkn_bench.training.data import Sequences, TrainingData
from fkn_bench.training.objectives import OBJECTIVES, innovation_nll, state_mse
from fkn_bench.training.pipeline import Trainable, TrainingOutcome, fit, trainable
from fkn_bench.training.trainer import DirectParameters, EpochRecord, NoiseModel, OnEpoch, SequenceModel, TrainConfig, Trainer

__all__ = [
    "OBJECTIVES",
    "DirectParameters",
    "EpochRecord",
    "NoiseModel",
    "OnEpoch",
    "SequenceModel",
    "Sequences",
    "Trainable",
    "TrainConfig",
    "Trainer",
    "TrainingData",
    "TrainingOutcome",
    "fit",
    "innovation_nll",
    "state_mse",
    "trainable",
]
