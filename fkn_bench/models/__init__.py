"""State-space models: one module per process model, registered in :mod:`fkn_bench.models.registry`.

The layer below the filters (and beside the truth simulator): a model is its transition and
Jacobian, its measurement, its noise layout and its sign and norm rules (:mod:`.base`), written
once for numpy arrays and torch tensors. Names are exported lazily (:mod:`fkn_bench.lazy`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from fkn_bench.lazy import lazy_exports

_EXPORTS = {
    "StateSpaceModel": ".base",
    "NoiseLayout": ".noise",
    "NoiseParameters": ".noise",
    "PoseTwistModel": ".pose_twist",
    "PAPER_MANUAL_LAYOUT": ".pose_twist",
    "RigidBodyModel": ".rigid_body",
    "LinearGaussianModel": ".linear",
    "ModelSpec": ".registry",
    "register_model": ".registry",
    "make_model": ".registry",
    "model_spec": ".registry",
    "model_names": ".registry",
    "DEFAULT_MODEL": ".registry",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())

if TYPE_CHECKING:
    from fkn_bench.models.base import StateSpaceModel
    from fkn_bench.models.linear import LinearGaussianModel
    from fkn_bench.models.noise import NoiseLayout, NoiseParameters
    from fkn_bench.models.pose_twist import PAPER_MANUAL_LAYOUT, PoseTwistModel
    from fkn_bench.models.registry import DEFAULT_MODEL, ModelSpec, make_model, model_names, model_spec, register_model
    from fkn_bench.models.rigid_body import RigidBodyModel
