"""Typed configuration options: a value from ``--set KEY=VALUE``, a TOML file or a sweep is checked
against the config field's annotation where it enters, so that ``--set hidden=abc`` reads
"config key 'hidden' must be an integer (got 'abc')" rather than a comparison error deep inside."""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Mapping
from typing import Any

__all__ = ["check_option_types"]

_NAMES = {int: "an integer", float: "a number", str: "a string", bool: "true or false", type(None): "none"}


def _accepts(kind: Any, value: Any) -> bool:
    origin = typing.get_origin(kind)
    if origin in (typing.Union, types.UnionType):
        return any(_accepts(k, value) for k in typing.get_args(kind))
    if kind is Any:
        return True
    if kind is type(None):
        return value is None
    if kind is bool:
        return isinstance(value, bool)
    if kind is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if kind is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if kind is str:
        return isinstance(value, str)
    if origin is tuple or kind is tuple:
        if not isinstance(value, (tuple, list)):
            return False
        args = typing.get_args(kind)
        if not args:
            return True
        if len(args) == 2 and args[1] is Ellipsis:
            return all(_accepts(args[0], v) for v in value)
        return len(args) == len(value) and all(_accepts(a, v) for a, v in zip(args, value))
    return True  # a type this check does not know: the config's own validation decides


def _describe(kind: Any) -> str:
    origin = typing.get_origin(kind)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_describe(k) for k in typing.get_args(kind))
    if origin is tuple or kind is tuple:
        args = typing.get_args(kind)
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of {_describe(args[0]).split(' ', 1)[-1]}s"
        return f"a list of {len(args)} values" if args else "a list"
    return _NAMES.get(kind, getattr(kind, "__name__", str(kind)))


def check_option_types(cls: type, data: Mapping[str, Any], label: str) -> None:
    """Raise ``ValueError`` naming the first key of ``data`` whose value does not fit the type of
    dataclass ``cls``'s field of that name, with what is valid (``label`` names the config,
    e.g. "FlexKalmanNet"). Keys that are not fields are left to the caller's unknown-key check."""
    hints = typing.get_type_hints(cls)
    fields = {f.name for f in dataclasses.fields(cls)}
    for key, value in data.items():
        if key in fields and key in hints and not _accepts(hints[key], value):
            raise ValueError(f"{label} config key {key!r} must be {_describe(hints[key])} (got {value!r})")
