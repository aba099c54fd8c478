"""The batched, differentiable Kalman filter core (torch, batch first, float64 by default)."""

from collections.abc import Sequence

from fkn_bench.filters.base import FilterResult, FilterState, KalmanFilter
from fkn_bench.filters.ekf import ExtendedKalmanFilter
from fkn_bench.filters.mekf import MEKF_MANUAL_LAYOUT, MultiplicativeEKF
from fkn_bench.filters.models import LinearGaussianModel, PoseTwistModel, StateSpaceModel
from fkn_bench.filters.parameters import NoiseLayout, NoiseParameters, ParameterSet
from fkn_bench.filters.rigid_body import RigidBodyModel
from fkn_bench.filters.ukf import UnscentedKalmanFilter

__all__ = [
    "MEKF_MANUAL_LAYOUT",
    "MultiplicativeEKF",
    "UnscentedKalmanFilter",
    "VARIANTS",
    "make_filter",
    "MODELS",
    "make_model",
    "RigidBodyModel",
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


MODELS = ("constant-velocity", "rigid-body", "rigid-body-ratios")
"""Process models by name: the paper's constant rate (:class:`PoseTwistModel`), the torque-free
rigid body with known inertia, and the rigid body with estimated inertia ratios
(:class:`RigidBodyModel`)."""


def make_model(name: str, *, inertia: Sequence[float] | None = None) -> StateSpaceModel:
    """Build a process model by name (see :data:`MODELS`). ``inertia``: principal moments
    ``(Jx, Jy, Jz)`` (kg m^2), required by ``rigid-body`` and the prior mean of the ratios of
    ``rigid-body-ratios`` (default: isotropic); the constant-velocity model takes none."""
    if name == "constant-velocity":
        if inertia is not None:
            raise ValueError("the constant-velocity model takes no inertia")
        return PoseTwistModel()
    if name in ("rigid-body", "rigid-body-ratios"):
        return RigidBodyModel(inertia=inertia, estimate_ratios=name == "rigid-body-ratios")
    raise ValueError(f"unknown process model {name!r}; valid models: {', '.join(MODELS)}")
