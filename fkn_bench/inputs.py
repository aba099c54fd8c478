"""The kinds of numbers that the public entry points accept: one rule, one set of words.

The Gymnasium environments (``AstrobeeTumble-v0`` and :class:`~fkn_bench.envs.astrobee_tumble_vector.AstrobeeTumbleVectorEnv`:
actions and ``reset`` seeds) and the estimator API (the pose of an online observation, the
measurements of a batch) check their inputs here, so that an input is accepted or refused, with
the same message, at every entry point. Every refusal is a one-line ``ValueError`` that names
the argument and what was wrong with it.

Arrays of numbers (:func:`real_array`): an ``ndarray``, a (nested) list or tuple, or a scalar,
whose numpy dtype (``np.asarray(value).dtype``: for a list, the dtype numpy infers from its
items) is a real integer or floating type (kind ``i``, ``u`` or ``f``), converted to float64.
Refused:

* strings (numeric ones too: ``"1.0"`` is not read as a number), bools, complex numbers (an
  imaginary part is never dropped), datetimes, bytes, and object arrays holding anything other
  than real numbers;
* ragged nestings (``[1.0, [2.0]]``) and any other shape than the expected one (no
  broadcasting and no squeezing: a 0-d array or an extra axis is a wrong shape);
* a value that float64 cannot hold (beyond +-1.8e308: a Python integer such as ``10**400``, or
  a long double), which would otherwise be read as ``inf`` or raise ``OverflowError``.

An object array of real numbers (what numpy makes of a list that mixes floats with integers too
large for int64) is converted entry by entry under the same rules. Non-finite values (NaN, +-inf)
pass: what they mean is the caller's rule (a missing measurement; an action refuses them).

One number (:func:`real_number`: ``dt``, an observation's ``time``): the same rules for a
scalar (a 0-d array of a real dtype is a scalar there). Counts (:func:`check_count`:
``num_envs``, ``chunk_size``): a Python or numpy integer >= 1, not a bool or a float.

Seeds (:func:`check_seed`): an integer (a Python ``int`` or a numpy integer; not a bool, a
float, a string or an array) in ``[0, SEED_LIMIT)``. Gymnasium's own rule is "a non-negative
int"; the upper bound :data:`SEED_LIMIT` = 2**63 is this project's, because episode seeds are
stored as int64 (the vector environment's ``info["episode_seed"]``, datasets, recordings): a
larger seed is refused, not wrapped or mapped onto another episode.
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np

from fkn_bench.types import ArrayF

__all__ = ["SEED_LIMIT", "check_count", "check_seed", "describe", "real_array", "real_number"]

SEED_LIMIT = 2**63
"""Seeds lie in ``[0, SEED_LIMIT)``: they are stored as int64 (module docstring)."""

_REAL_KINDS = frozenset("iuf")


def describe(value: Any) -> str:
    """A short ``repr`` of ``value`` for a one-line message: an integer of more than 30 digits
    by its digit count, anything else cut at 60 characters."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool) and abs(int(value)) >= 10**30:
        return f"an integer of {len(str(abs(int(value))))} digits"
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def check_seed(seed: Any, name: str = "seed") -> int:
    """``seed`` as a Python ``int``: an integer in ``[0, SEED_LIMIT)`` (module docstring), else
    a ``ValueError`` naming ``name``."""
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise ValueError(f"{name} must be a non-negative integer (got {describe(seed)})")
    value = int(seed)
    if value < 0:
        raise ValueError(f"{name} must be a non-negative integer (got {value})")
    if value >= SEED_LIMIT:
        raise ValueError(f"{name} must be below 2**63, seeds are stored as int64 (got {describe(value)})")
    return value


def check_count(value: Any, name: str) -> int:
    """``value`` as a Python ``int`` >= 1 (a Python or numpy integer; not a bool, a float or a
    string), else a ``ValueError`` naming ``name``: ``num_envs``, ``chunk_size``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be an integer >= 1 (got {describe(value)})")
    return int(value)


def real_number(value: Any, name: str, what: str = "a real number") -> float:
    """One number as a float under the rules of :func:`real_array` (a Python or numpy integer or
    float, or a 0-d array of one; not a bool, a string or a complex number; nothing float64
    cannot hold), else a ``ValueError`` naming ``name`` (``f"{name} must be {what}"``). NaN and
    +-inf pass: what they mean is the caller's rule."""
    if type(value) is float:
        return value
    if isinstance(value, np.ndarray) and value.shape == ():
        value = value[()]
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be {what} (got {describe(value)})")
    return _as_float(value, name)


def _as_float(item: Any, entry: str) -> float:
    """A real number as a float; ``ValueError`` naming ``entry`` where float64 cannot hold it."""
    try:
        out = float(item)
    except OverflowError:
        out = math.inf
    if abs(out) == math.inf and not (item == math.inf or item == -math.inf):  # 10**400, a long double
        raise ValueError(f"{entry} is {describe(item)}, beyond float64's range (+-1.8e308)")
    return out


def _index(name: str, position: tuple[int, ...]) -> str:
    return f"{name}[{', '.join(str(int(i)) for i in position)}]" if position else name


def real_array(
    value: Any, name: str, shape: tuple[int, ...] | None = None, *, shape_text: str | None = None, entry: str | None = None
) -> ArrayF:
    """``value`` as a float64 array under the module's rules, else a ``ValueError`` naming
    ``name``: ``shape`` is the exact shape required (None: any; ``shape_text`` then says in
    messages what shape is meant, e.g. ``"(B, T, 7)"``); ``entry`` names the array's entries in
    messages (``entry[0]``; default ``name``). May return ``value`` itself when it is already a
    float64 ``ndarray``."""
    entry = name if entry is None else entry
    wanted = f"a float array of shape {shape_text or shape}" if (shape_text or shape) is not None else "a float array"
    if isinstance(value, np.ndarray):
        array = value
    else:
        try:
            array = np.asarray(value)
        except ValueError:  # a ragged nesting (numpy >= 1.24 refuses it)
            raise ValueError(f"{name} must be {wanted} (got a ragged nesting: {describe(value)})") from None
        except (TypeError, RuntimeError) as exc:  # e.g. a GPU tensor, or one that requires grad
            raise ValueError(f"{name} must be {wanted} (got {type(value).__name__}, not readable as one: {exc})") from None
    kind = array.dtype.kind
    if kind == "O":
        array = _real_objects(array, name, wanted, entry)
    elif kind not in _REAL_KINDS:
        raise ValueError(
            f"{name} must be {wanted} (a real integer or floating dtype; got dtype {array.dtype})"
        )
    if shape is not None and array.shape != shape:
        raise ValueError(f"{name} must have shape {shape} (got {array.shape})")
    if array.dtype == np.float64:
        return array
    if kind == "f" and array.dtype.itemsize > 8:  # a long double: may hold what float64 cannot
        with np.errstate(over="ignore"):
            out = array.astype(np.float64)
        lost = np.isinf(out) & np.isfinite(array)
        if lost.any():
            position = tuple(np.argwhere(lost)[0])
            raise ValueError(f"{_index(entry, position)} is {str(array[position])}, beyond float64's range (+-1.8e308)")
        return out
    return array.astype(np.float64)


def _real_objects(array: np.ndarray, name: str, wanted: str, entry: str) -> ArrayF:
    """An object array of real numbers converted to float64, entry by entry."""
    out = np.empty(array.shape, dtype=np.float64)
    for position, item in np.ndenumerate(array):
        if isinstance(item, (bool, np.bool_)) or not isinstance(item, numbers.Real):
            raise ValueError(
                f"{name} must be {wanted} (a real integer or floating dtype; "
                f"got dtype object holding {type(item).__name__} {describe(item)} at {_index(entry, position)})"
            )
        out[position] = _as_float(item, _index(entry, position))
    return out

