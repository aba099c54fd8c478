"""KalmanNet (Revach, Shlezinger, Ni, Lopez Escoriza, van Sloun & Eldar, "KalmanNet: Neural
Network Aided Kalman Filtering for Partially Known Dynamics", IEEE Trans. Signal Processing 70,
2022), architecture 2: a recurrent network computes the Kalman gain inside the filter loop; and
Recursive KalmanNet (Mortada, Falcon, Kahil, Clavaud & Michel, "Recursive KalmanNet: Deep
Learning-Augmented Kalman Filtering for State Estimation with Consistent Uncertainty
Quantification", EUSIPCO 2025), which learns the error covariance beside the gain
(:mod:`fkn_bench.kalmannet.recursive`); Split-KalmanNet (Choi, Park, Shlezinger, Eldar & Lee, "Split-KalmanNet:
A Robust Model-Based Deep Learning Approach for State Estimation", IEEE Trans. Vehicular Technology
72(9), 2023), whose two networks learn the gain's prior and innovation covariances
(:mod:`fkn_bench.kalmannet.split`); and Cholesky-KalmanNet (Ko & Shafieezadeh, "Cholesky-KalmanNet:
Model-Based Deep Learning with Positive Definite Error Covariance Structure", IEEE Signal
Processing Letters, 2025), which learns them as Cholesky factors (:mod:`fkn_bench.kalmannet.cholesky`).
The synthetic examples of their papers: :mod:`fkn_bench.kalmannet.linear` (KalmanNet) and
:mod:`fkn_bench.kalmannet.rotation` (Split- and Cholesky-KalmanNet)."""

from fkn_bench.kalmannet.checkpoint import (
    CHOLESKY_TRAINABLE,
    RECURSIVE_TRAINABLE,
    SPLIT_TRAINABLE,
    TRAINABLE,
    build_cholesky_model,
    build_model,
    build_recursive_model,
    build_split_model,
    cholesky_model_from_checkpoint,
    model_from_checkpoint,
    recursive_model_from_checkpoint,
    split_model_from_checkpoint,
)
from fkn_bench.kalmannet.cholesky import CholeskyKalmanNet
from fkn_bench.kalmannet.config import CholeskyKalmanNetConfig, KalmanNetConfig, RecursiveKalmanNetConfig, SplitKalmanNetConfig
from fkn_bench.kalmannet.estimator import (
    CholeskyKalmanNetEstimator,
    KalmanNetEstimator,
    RecursiveKalmanNetEstimator,
    SplitKalmanNetEstimator,
    cholesky_kalmannet_factory,
    kalmannet_factory,
    recursive_kalmannet_factory,
    split_kalmannet_factory,
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
from fkn_bench.kalmannet.split import SplitHidden, SplitKalmanNet, SplitKalmanNetRun, SplitKalmanNetState

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
    "SPLIT_TRAINABLE",
    "SplitKalmanNetConfig",
    "SplitKalmanNetEstimator",
    "build_split_model",
    "split_kalmannet_factory",
    "split_model_from_checkpoint",
    "SplitHidden",
    "SplitKalmanNet",
    "SplitKalmanNetRun",
    "SplitKalmanNetState",
    "CHOLESKY_TRAINABLE",
    "CholeskyKalmanNetConfig",
    "CholeskyKalmanNetEstimator",
    "build_cholesky_model",
    "cholesky_kalmannet_factory",
    "cholesky_model_from_checkpoint",
    "CholeskyKalmanNet",
]
