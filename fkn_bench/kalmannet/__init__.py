"""KalmanNet (Revach, Shlezinger, Ni, Lopez Escoriza, van Sloun & Eldar, "KalmanNet: Neural
Network Aided Kalman Filtering for Partially Known Dynamics", IEEE Trans. Signal Processing 70,
2022), architecture 2: a recurrent network computes the Kalman gain inside the filter loop; and
Recursive KalmanNet (Mortada, Falcon, Kahil, Clavaud & Michel, "Recursive KalmanNet: Deep
Learning-Augmented Kalman Filtering for State Estimation with Consistent Uncertainty
Quantification", EUSIPCO 2025), which learns the error covariance beside the gain
(:mod:`fkn_bench.kalmannet.recursive`)."""

from fkn_bench.kalmannet.checkpoint import (
    RECURSIVE_TRAINABLE,
    TRAINABLE,
    build_model,
    build_recursive_model,
    model_from_checkpoint,
    recursive_model_from_checkpoint,
)
from fkn_bench.kalmannet.config import KalmanNetConfig, RecursiveKalmanNetConfig
from fkn_bench.kalmannet.estimator import (
    KalmanNetEstimator,
    RecursiveKalmanNetEstimator,
    kalmannet_factory,
    recursive_kalmannet_factory,
)
from fkn_bench.kalmannet.manifolds import Euclidean, Manifold, PoseTangent, manifold_for
from fkn_bench.kalmannet.network import GainNetwork, Hidden, normalize_features
from fkn_bench.kalmannet.recursion import KalmanNet, KalmanNetRun, KalmanNetState, ManifoldRecursion
from fkn_bench.kalmannet.recursive import (
    GRUBranch,
    RecursiveHidden,
    RecursiveKalmanNet,
    RecursiveKalmanNetRun,
    RecursiveKalmanNetState,
)

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
    "ManifoldRecursion",
    "RECURSIVE_TRAINABLE",
    "RecursiveKalmanNetConfig",
    "RecursiveKalmanNetEstimator",
    "build_recursive_model",
    "recursive_kalmannet_factory",
    "recursive_model_from_checkpoint",
    "GRUBranch",
    "RecursiveHidden",
    "RecursiveKalmanNet",
    "RecursiveKalmanNetRun",
    "RecursiveKalmanNetState",
]
