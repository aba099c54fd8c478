"""Typed configuration options: a value from ``--set KEY=VALUE``, a TOML file or a sweep is checked
against the config field's annotation where it enters (:mod:`fkn_bench.config_values`: numbers are
finite numbers, never booleans or numeric strings), so that ``--set hidden=abc`` reads
"config key 'hidden' must be an integer (got 'abc')" rather than a comparison error deep inside,
and ``lr = nan`` in a TOML file reads "best.toml: FlexKalmanNet config key 'lr' must be a finite
number (got nan)": a key that came from a configuration file (:class:`FileOptions`) is reported
with the file's name."""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Mapping
from typing import Any

from fkn_bench.config_values import accepts, describe_kind

__all__ = ["FileOptions", "check_option_types", "naming_the_file"]


class FileOptions(dict):  # type: ignore[type-arg]
    """Options some of which were read from a configuration file: ``sources`` maps those keys to
    the file (what error messages name)."""

    def __init__(self, values: Mapping[str, Any], sources: Mapping[str, str]) -> None:
        super().__init__(values)
        self.sources = dict(sources)


def _source(data: Mapping[str, Any], key: str) -> str:
    """``"<file>: "`` when ``key`` of ``data`` came from a configuration file, else ``""``."""
    source = getattr(data, "sources", {}).get(key)
    return f"{source}: " if source else ""


def check_option_types(cls: type, data: Mapping[str, Any], label: str) -> None:
    """Raise ``ValueError`` naming the first key of ``data`` whose value does not fit the type of
    dataclass ``cls``'s field of that name, with what is valid (``label`` names the config,
    e.g. "FlexKalmanNet"; a key read from a file: the file too). Keys that are not fields are
    left to the caller's unknown-key check."""
    hints = typing.get_type_hints(cls)
    fields = {f.name for f in dataclasses.fields(cls)}
    for key, value in data.items():
        if key in fields and key in hints and not accepts(hints[key], value):
            raise ValueError(f"{_source(data, key)}{label} config key {key!r} must be {describe_kind(hints[key])} "
                             f"(got {value!r})")


def naming_the_file(exc: Exception, data: Mapping[str, Any]) -> ValueError:
    """``exc`` (a config's own refusal, "<key> must be ...") as a ``ValueError`` that names the
    configuration file ``<key>`` came from, when it came from one."""
    key = str(exc).split(" ", 1)[0].strip("'\":")
    return ValueError(f"{_source(data, key)}{exc}")
