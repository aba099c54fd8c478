"""Plausibility of true states read from files (recordings and datasets), checked before scoring.

A true state ``[q (wxyz), r (m), w (rad/s), v (m/s)]`` read from a file is refused (a named
error of the reader: file, episode or topic, step or message) when it is not *plausible*:

* any component is not finite (NaN, +-inf);
* a position component is beyond +-:data:`POSITION_LIMIT` (1e6 m: a thousand kilometres, where
  the International Space Station is about 110 m across; a recording in a frame that far from its
  origin is not an Astrobee's);
* an angular-rate (rad/s) or velocity (m/s) component is beyond +-:data:`RATE_LIMIT` (1e3: at
  1e3 rad/s a 10 Hz sample turns by about 16 revolutions between two steps);
* the attitude quaternion's norm is off 1 by more than the tolerance (default
  :data:`QUATERNION_TOLERANCE`, 1e-6; the simulator's are within 1e-15).

Such values are not scored: a NaN truth makes the seed's score NaN, which an average over seeds
would otherwise leave out without a word, and 1e300 overflows the squared errors, which would read
as the estimator diverging. Recorded poses and twists (truth and measurement topics) are held to
the same position and rate limits when they are read (:mod:`fkn_bench.recordings.base`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fkn_bench.types import STATE_NAMES, ArrayF

__all__ = ["POSITION_LIMIT", "RATE_LIMIT", "QUATERNION_TOLERANCE", "component_limits", "first_implausible"]

POSITION_LIMIT = 1e6
"""Largest plausible magnitude of a position component, m (module docstring)."""
RATE_LIMIT = 1e3
"""Largest plausible magnitude of an angular-rate (rad/s) or velocity (m/s) component."""
QUATERNION_TOLERANCE = 1e-6
"""Largest plausible ``| |q| - 1 |`` of a true attitude quaternion."""

_LIMITS = {"q": (np.inf, ""), "r": (POSITION_LIMIT, " m"), "w": (RATE_LIMIT, " rad/s"), "v": (RATE_LIMIT, " m/s")}


def component_limits(components: Sequence[str] = STATE_NAMES) -> ArrayF:
    """The largest plausible magnitude of each named state component (:data:`POSITION_LIMIT` for
    ``r*``, :data:`RATE_LIMIT` for ``w*`` and ``v*``, infinity for the quaternion's ``q*``)."""
    return np.array([_LIMITS[name[0]][0] for name in components])


def first_implausible(
    values: ArrayF, components: Sequence[str] = STATE_NAMES, *, quaternion_tolerance: float | None = QUATERNION_TOLERANCE
) -> tuple[tuple[int, ...], str] | None:
    """The first implausible row of ``values`` (``(..., len(components))``) under the rules of the
    module docstring, as ``(its index over the leading axes, what is wrong)``, or None.

    ``components`` names the columns (state names, :data:`~fkn_bench.types.STATE_NAMES`; their
    first letter picks the limit: ``q`` none, ``r`` position, ``w``/``v`` rate). With
    ``quaternion_tolerance`` (not None) the norm of the ``qw qx qy qz`` columns is checked too.
    Rows are searched in C order; the message names the component and its value, e.g.
    ``"rx = 1e+300 m is beyond +-1e+06 m"``.
    """
    values = np.asarray(values, dtype=np.float64)
    if values.shape[-1:] != (len(components),):
        raise ValueError(f"values must have shape (..., {len(components)}) (got {values.shape})")
    ok = np.isfinite(values) & (np.abs(values) <= component_limits(components))
    rows_ok = ok.all(axis=-1)
    quaternion = [list(components).index(q) for q in ("qw", "qx", "qy", "qz") if q in components]
    if quaternion_tolerance is not None and len(quaternion) == 4:
        with np.errstate(invalid="ignore", over="ignore"):
            rows_ok &= np.abs(np.linalg.norm(values[..., quaternion], axis=-1) - 1.0) <= quaternion_tolerance
    if rows_ok.all():
        return None
    row = np.unravel_index(int(np.argmax(~rows_ok.ravel())), rows_ok.shape)
    index = tuple(int(i) for i in row)
    if ok[row].all():
        norm = float(np.linalg.norm(values[row][quaternion]))
        return index, f"the attitude quaternion has norm {norm:.9g}, not 1 (tolerance {quaternion_tolerance:g})"
    column = int(np.argmax(~ok[row]))
    name, value = components[column], float(values[row][column])
    limit, unit = _LIMITS[name[0]]
    if not np.isfinite(value):
        return index, f"{name} = {value} is not finite"
    return index, f"{name} = {value:.6g}{unit} is beyond +-{limit:g}{unit}"
