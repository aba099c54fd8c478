"""The batched, differentiable Kalman filter core (torch, batch first, float64 by default)."""

from fkn_bench.filters.base import FilterResult, FilterState, KalmanFilter
from fkn_bench.filters.ekf import ExtendedKalmanFilter
from fkn_bench.filters.models import LinearGaussianModel, PoseTwistModel, StateSpaceModel
from fkn_bench.filters.parameters import NoiseLayout, NoiseParameters, ParameterSet

__all__ = [
    "ExtendedKalmanFilter",
    "FilterResult",
    "FilterState",
    "KalmanFilter",
    "LinearGaussianModel",
    "NoiseLayout",
    "NoiseParameters",
    "ParameterSet",
    "PoseTwistModel",
    "StateSpaceModel",
]
