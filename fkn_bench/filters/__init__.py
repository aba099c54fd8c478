"""The batched, differentiable Kalman filter core (torch, batch first, float64 by default).

The filters run any state-space model of :mod:`fkn_bench.models`; this package holds the filter
variants (:data:`VARIANTS`), their recursion (:mod:`.base`) and the learnable parameter sets
(:mod:`.parameters`).
"""

from fkn_bench.filters.base import FilterResult, FilterState, KalmanFilter
from fkn_bench.filters.ekf import ExtendedKalmanFilter
from fkn_bench.filters.mekf import MEKF_MANUAL_LAYOUT, MultiplicativeEKF
from fkn_bench.filters.parameters import ParameterSet
from fkn_bench.filters.ukf import UnscentedKalmanFilter

__all__ = [
    "MEKF_MANUAL_LAYOUT",
    "MultiplicativeEKF",
    "UnscentedKalmanFilter",
    "VARIANTS",
    "make_filter",
    "ExtendedKalmanFilter",
    "FilterResult",
    "FilterState",
    "KalmanFilter",
    "ParameterSet",
]

VARIANTS: dict[str, type[KalmanFilter]] = {
    "ekf": ExtendedKalmanFilter,
    "ukf": UnscentedKalmanFilter,
    "mekf": MultiplicativeEKF,
}
"""Filter variants by name: interchangeable behind :class:`KalmanFilter`."""


def make_filter(name: str, **options: object) -> KalmanFilter:
    """Build a filter variant by name (``ekf``, ``ukf`` or ``mekf``)."""
    try:
        cls = VARIANTS[name]
    except KeyError:
        raise ValueError(f"unknown filter variant {name!r}; valid variants: {', '.join(VARIANTS)}") from None
    return cls(**options)  # type: ignore[arg-type]
