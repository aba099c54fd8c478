"""Shared names, index layouts and type aliases of fkn-bench.

Conventions used everywhere in the project (convert only at the edges):

* Quaternions are Hamilton, scalar first ``[qw, qx, qy, qz]`` and describe the rotation
  from the body frame to the world frame (``v_world = q (x) v_body (x) q*``).
* The state is ``x = [qw, qx, qy, qz, rx, ry, rz, wx, wy, wz, vx, vy, vz]`` (13): attitude,
  position in m, angular velocity in rad/s expressed in the **world** frame, and velocity in m/s
  (Pinheiro-Torres Vogt et al., FlexKalmanNet, eq. 6).
* A pose measurement is ``y = [qw, qx, qy, qz, rx, ry, rz]`` (7); a missing one holds NaN and
  its validity flag is 0.
* The 12-dimensional *error* state used for consistency metrics and by the multiplicative EKF is
  ``[dtheta(3), dr(3), dw(3), dv(3)]`` with the attitude error a world-frame rotation vector:
  ``q_true = exp(dtheta / 2) (x) q_est``.
* Arrays are batch first: ``(B, T, 13)`` for state sequences, ``(B, T, 7)`` for measurements and
  ``(B, T)`` for validity masks.

Shapes in signatures are written in jaxtyping's notation, without the package or its run-time
checks (``fkn_bench/DESIGN.md``, "Performance notes"): ``Float[ArrayF, "B T 13"]`` is
``typing.Annotated[ArrayF, "B T 13"]``, a float64 numpy array of shape ``(B, T, 13)``;
``Float[Tensor, "B T 7"]`` a torch tensor; ``Bool[ArrayB, "B T"]`` a mask. Axis names: ``B``
sequences (batch), ``T`` time steps, ``N`` rows of a flattened batch, ``n`` any state-like size,
``...`` any leading axes; a number is a fixed size. Nothing checks them at run time (type checkers
read ``Float[X, ...]`` as ``X``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, TypeAlias, Union
from typing import Annotated as Bool  # Bool[ArrayB, "B T"]: a boolean array with those axes
from typing import Annotated as Float  # Float[ArrayF, "B T 13"]: a float array with those axes

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from torch import Tensor

__all__ = [
    "ArrayF",
    "ArrayB",
    "Array",
    "Float",
    "Bool",
    "STATE_DIM",
    "MEASUREMENT_DIM",
    "ERROR_DIM",
    "POSE_ERROR_DIM",
    "STATE_NAMES",
    "MEASUREMENT_NAMES",
    "ERROR_NAMES",
    "STATE_UNITS",
    "ATTITUDE",
    "POSITION",
    "OMEGA",
    "VELOCITY",
    "STATE_GROUPS",
]

ArrayF: TypeAlias = npt.NDArray[np.float64]
"""A float64 numpy array (shapes are given in each docstring)."""
ArrayB: TypeAlias = npt.NDArray[np.bool_]
"""A boolean numpy array."""
Array: TypeAlias = Union[npt.NDArray[Any], "Tensor"]
"""A numpy array or a torch tensor: code written once for both (:func:`fkn_bench.linalg.namespace`)."""

STATE_DIM = 13
MEASUREMENT_DIM = 7
ERROR_DIM = 12
POSE_ERROR_DIM = 6

STATE_NAMES: tuple[str, ...] = (
    "qw", "qx", "qy", "qz", "rx", "ry", "rz", "wx", "wy", "wz", "vx", "vy", "vz",
)
MEASUREMENT_NAMES: tuple[str, ...] = STATE_NAMES[:7]
ERROR_NAMES: tuple[str, ...] = (
    "dthx", "dthy", "dthz", "drx", "dry", "drz", "dwx", "dwy", "dwz", "dvx", "dvy", "dvz",
)
STATE_UNITS: tuple[str, ...] = ("1",) * 4 + ("m",) * 3 + ("rad/s",) * 3 + ("m/s",) * 3

ATTITUDE = slice(0, 4)
POSITION = slice(4, 7)
OMEGA = slice(7, 10)
VELOCITY = slice(10, 13)

STATE_GROUPS: dict[str, slice] = {
    "attitude": ATTITUDE,
    "position": POSITION,
    "omega": OMEGA,
    "velocity": VELOCITY,
}
"""The four state groups of the paper's figures, as slices of the 13-dim state."""
