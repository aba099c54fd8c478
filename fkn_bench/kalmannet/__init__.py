"""KalmanNet (Revach, Shlezinger, Ni, Lopez Escoriza, van Sloun & Eldar, "KalmanNet: Neural
Network Aided Kalman Filtering for Partially Known Dynamics", IEEE Trans. Signal Processing 70,
2022), architecture 2: a recurrent network computes the Kalman gain inside the filter loop."""

from fkn_bench.kalmannet.checkpoint import TRAINABLE, build_model, model_from_checkpoint
from fkn_bench.kalmannet.config import KalmanNetConfig
from fkn_bench.kalmannet.estimator import KalmanNetEstimator, kalmannet_factory
from fkn_bench.kalmannet.manifolds import Euclidean, Manifold, PoseTangent, manifold_for
from fkn_bench.kalmannet.network import GainNetwork, Hidden, normalize_features
from fkn_bench.kalmannet.recursion import KalmanNet, KalmanNetRun, KalmanNetState

__all__ = [
    "TRAINABLE",
    "KalmanNetConfig",
    "KalmanNetEstimator",
    "build_model",
    "kalmannet_factory",
    "model_from_checkpoint",
    "Euclidean",
    "GainNetwork",
    "Hidden",
    "KalmanNet",
    "KalmanNetRun",
    "KalmanNetState",
    "Manifold",
    "PoseTangent",
    "manifold_for",
    "normalize_features",
]
