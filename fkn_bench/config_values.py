"""Configuration values checked against the annotation of what they feed: one rule for a TOML
file, a JSON file (a saved estimator, a learned-parameter artefact), ``--set KEY=VALUE`` and a
sweep trial.

A value is accepted for an annotation (:func:`accepts`) when it is of that kind:

* ``float``: a number (``int`` or ``float``, never ``bool``) that is finite (TOML's ``nan`` and
  ``inf`` and JSON's ``NaN`` and ``Infinity`` are refused, as is an integer beyond float range);
* ``int``: an ``int``, never ``bool`` (``true`` is not 1) nor a float;
* ``bool``: ``true`` or ``false`` only; ``str``: a string (a ``Path`` field takes one too);
* ``Sequence[X]``, ``list[X]``, ``tuple[X, ...]``: a list or tuple (never a string) of ``X``;
  ``tuple[X, Y]``: exactly that many; ``Mapping``/``dict``: an object;
* ``Literal[...]``: one of its values; ``X | Y`` and ``Optional[X]``: either.

A numeric string (``"0.1"``) is not a number anywhere. Types this check does not know (arrays,
tensors, ``Any``) are left to the receiver's own validation, as are ranges (a standard deviation
must also be > 0: the filter says so). Errors are one-line ``ValueError``s naming the key and the
kind expected; callers prefix the file.
"""

from __future__ import annotations

import collections.abc as abc
import math
import types
import typing
from collections.abc import Mapping
from pathlib import PurePath
from typing import Any

__all__ = ["accepts", "describe_kind", "check_arguments", "init_annotations"]

_NAMES = {int: "an integer", float: "a finite number", str: "a string", bool: "true or false", type(None): "none"}
_SEQUENCES = (list, tuple, abc.Sequence, abc.MutableSequence)
_MAPPINGS = (dict, abc.Mapping, abc.MutableMapping)


def _finite(value: Any) -> bool:
    try:
        return math.isfinite(value)
    except OverflowError:  # an int beyond float range
        return False


def accepts(kind: Any, value: Any) -> bool:
    """Whether ``value`` is of the kind annotation ``kind`` describes (module docstring)."""
    origin = typing.get_origin(kind)
    if origin in (typing.Union, types.UnionType):
        return any(accepts(k, value) for k in typing.get_args(kind))
    if origin is typing.Literal:
        return any(value == v and type(value) is type(v) for v in typing.get_args(kind))
    if kind is Any:
        return True
    if kind is type(None) or kind is None:
        return value is None
    if kind is bool:
        return isinstance(value, bool)
    if kind is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if kind is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool) and _finite(value)
    if kind is str:
        return isinstance(value, str)
    if isinstance(kind, type) and issubclass(kind, PurePath):
        return isinstance(value, (str, PurePath))
    container = origin or kind
    if container in _SEQUENCES:
        if not isinstance(value, (list, tuple)):
            return False
        args = typing.get_args(kind)
        if not args:
            return True
        if container is tuple and not (len(args) == 2 and args[1] is Ellipsis):
            return len(args) == len(value) and all(accepts(a, v) for a, v in zip(args, value))
        return all(accepts(args[0], v) for v in value)
    if container in _MAPPINGS:
        return isinstance(value, dict)
    return True  # a type this check does not know: the receiver's own validation decides


def describe_kind(kind: Any) -> str:
    """``kind`` in words: "a finite number", "a list of finite numbers", "an integer or none"."""
    origin = typing.get_origin(kind)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(dict.fromkeys(describe_kind(k) for k in typing.get_args(kind)))
    if origin is typing.Literal:
        return "one of " + ", ".join(repr(v) for v in typing.get_args(kind))
    container = origin or kind
    if container in _SEQUENCES:
        args = typing.get_args(kind)
        if container is tuple and args and not (len(args) == 2 and args[1] is Ellipsis):
            return f"a list of {len(args)} values"
        if not args:
            return "a list"
        return "a list of " + " or ".join(_plural(part) for part in describe_kind(args[0]).split(" or "))
    if container in _MAPPINGS:
        return "an object"
    if isinstance(kind, type) and issubclass(kind, PurePath):
        return "a path (string)"
    return _NAMES.get(kind, getattr(kind, "__name__", str(kind)))


def _plural(words: str) -> str:
    """"a finite number" -> "finite numbers", "a list of integers" -> "lists of integers"."""
    if not words.startswith(("a ", "an ")):
        return words
    head, of, tail = words.split(" ", 1)[1].partition(" of ")
    return f"{head}s{of}{tail}"


def init_annotations(cls: type) -> dict[str, Any]:
    """The annotations of the keyword arguments of ``cls(...)``: its ``__init__``'s, and for an
    ``__init__`` that passes ``**config`` on, its bases' (the nearest class first). A class whose
    annotations cannot be resolved contributes none (its own validation decides)."""
    found: dict[str, Any] = {}
    for klass in cls.__mro__:
        init = klass.__dict__.get("__init__")
        if init is None or klass is object:
            continue
        try:
            hints = typing.get_type_hints(init)
        except Exception:  # noqa: BLE001 - a name only imported for type checkers
            continue
        for name, kind in hints.items():
            if name != "return":
                found.setdefault(name, kind)
    return found


def check_arguments(annotations: Mapping[str, Any], values: Mapping[str, Any], where: str) -> None:
    """Raise ``ValueError`` (``"<where>: 'key' must be <kind> (got <value>)"``, without ``where``
    when it is empty) for the first key of ``values`` whose value is not of its annotation's kind;
    keys without one are left alone."""
    for key, value in values.items():
        kind = annotations.get(key)
        if kind is not None and not accepts(kind, value):
            shown = repr(value)
            raise ValueError(f"{where}: " * bool(where) + f"{key!r} must be {describe_kind(kind)} (got "
                             f"{shown if len(shown) <= 60 else shown[:57] + '...'})")
