"""The one place process models are registered by name.

The trainer, the artefacts, the estimators and the CLI read models from here: a new process
model is one module (a :class:`~fkn_bench.models.base.StateSpaceModel`) plus one
:func:`register_model` call; third-party packages register theirs through the entry-point group
:data:`ENTRY_POINT_GROUP` (each entry point a callable that registers, or a module whose import
does).
"""

from __future__ import annotations

import importlib.metadata
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

from fkn_bench.models.base import StateSpaceModel

__all__ = ["ModelSpec", "register_model", "make_model", "model_spec", "model_names", "DEFAULT_MODEL", "ENTRY_POINT_GROUP"]

ENTRY_POINT_GROUP = "fkn_bench.models"
DEFAULT_MODEL = "constant-velocity"
"""The paper's process model; configs omit ``model`` when it is this one."""

InertiaUse = Literal["none", "required", "prior"]


@dataclass(frozen=True)
class ModelSpec:
    """A registered process model.

    Attributes:
        name: the name configs and the CLI use.
        build: ``build(inertia)`` -> the model; ``inertia`` the principal moments
            ``(Jx, Jy, Jz)`` in kg m^2, or None.
        inertia: how the model uses ``inertia``: ``"none"`` (takes none), ``"required"`` (known
            moments; an estimator without them takes its scenario's) or ``"prior"`` (the prior
            mean of estimated inertia ratios; None: isotropic).
        description: one line for listings and ``--help``.
    """

    name: str
    build: Callable[[tuple[float, float, float] | None], StateSpaceModel]
    inertia: InertiaUse
    description: str


_REGISTRY: dict[str, ModelSpec] = {}
_LOADED = False


def register_model(name: str, build: Callable[[tuple[float, float, float] | None], StateSpaceModel], *,
                   inertia: InertiaUse = "none", description: str = "", overwrite: bool = False) -> ModelSpec:
    """Register a process model under ``name`` (see :class:`ModelSpec`); ValueError on a taken
    name unless ``overwrite``."""
    if not isinstance(name, str) or not name or any(c.isspace() for c in name):
        raise ValueError(f"model name must be a non-empty string without spaces (got {name!r})")
    if inertia not in ("none", "required", "prior"):
        raise ValueError(f"inertia must be 'none', 'required' or 'prior' (got {inertia!r})")
    if name in _REGISTRY and not overwrite:
        raise ValueError(f"process model {name!r} is already registered (pass overwrite=True to replace it)")
    _REGISTRY[name] = spec = ModelSpec(name, build, inertia, description)
    return spec


def _ensure_loaded() -> None:
    global _LOADED
    if _LOADED:
        return
    _LOADED = True
    for entry_point in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        loaded = entry_point.load()
        if callable(loaded):
            loaded()


def model_names() -> tuple[str, ...]:
    """Registered model names, the built-in ones first."""
    _ensure_loaded()
    return tuple(_REGISTRY)


def model_spec(name: str) -> ModelSpec:
    """The spec of model ``name``; ValueError listing the valid names otherwise."""
    _ensure_loaded()
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown process model {name!r}; valid models: {', '.join(_REGISTRY)}") from None


def make_model(name: str, *, inertia: Sequence[float] | None = None) -> StateSpaceModel:
    """Build process model ``name``; ``inertia`` (principal moments, kg m^2) as its spec says:
    required by a known-inertia model, a prior mean for estimated ratios, refused by a model that
    takes none."""
    spec = model_spec(name)
    if spec.inertia == "none" and inertia is not None:
        raise ValueError(f"the {name} model takes no inertia")
    return spec.build(None if inertia is None else tuple(float(v) for v in inertia))  # type: ignore[arg-type]


def _pose_twist(inertia: tuple[float, float, float] | None) -> StateSpaceModel:
    from fkn_bench.models.pose_twist import PoseTwistModel

    return PoseTwistModel()


def _rigid_body(estimate_ratios: bool) -> Callable[[tuple[float, float, float] | None], StateSpaceModel]:
    def build(inertia: tuple[float, float, float] | None) -> StateSpaceModel:
        from fkn_bench.models.rigid_body import RigidBodyModel

        return RigidBodyModel(inertia=inertia, estimate_ratios=estimate_ratios)

    return build


register_model(DEFAULT_MODEL, _pose_twist, description="the paper's constant world-frame rate and velocity (FlexKalmanNet eqs. 6-11)")
register_model("rigid-body", _rigid_body(False), inertia="required",
               description="torque-free rigid body with known principal moments (Euler's equations, RK4)")
register_model("rigid-body-ratios", _rigid_body(True), inertia="prior",
               description="torque-free rigid body with its two log inertia ratios estimated in the state")
