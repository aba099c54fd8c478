"""FlexKalmanNet: a fully connected network that learns Kalman-filter parameters, trained through
the filter recursion (Pinheiro-Torres Vogt, Huwald, Ben-Larbi & Stoll)."""

from fkn_bench.flexkalmannet.checkpoint import build_model, model_from_checkpoint, train_flexkalmannet
from fkn_bench.flexkalmannet.config import DEVIATIONS, PAPER_TABLE, FlexKalmanNetConfig
from fkn_bench.flexkalmannet.estimator import AdaptiveFlexKalmanNetEstimator, FlexKalmanNetEstimator
from fkn_bench.flexkalmannet.network import FlexKalmanNet, FlexKalmanNetwork
from fkn_bench.training.checkpoint import CheckpointError, load_checkpoint

__all__ = [
    "DEVIATIONS",
    "PAPER_TABLE",
    "AdaptiveFlexKalmanNetEstimator",
    "CheckpointError",
    "FlexKalmanNet",
    "FlexKalmanNetConfig",
    "FlexKalmanNetEstimator",
    "FlexKalmanNetwork",
    "build_model",
    "load_checkpoint",
    "model_from_checkpoint",
    "train_flexkalmannet",
]
