"""Command-line options shared by several subcommands."""

from __future__ import annotations

import argparse
from typing import Any

from fkn_bench.cli import UsageError

__all__ = [
    "add_command", "add_scenario_file_option", "load_scenario_files", "check_minimum", "parse_value", "parse_key_values",
]


def add_command(subparsers: argparse._SubParsersAction, name: str, help: str, doc: str | None) -> argparse.ArgumentParser:
    """Register subcommand ``name`` with its module docstring ``doc`` as the description (kept as
    written: examples and lists stay readable in ``--help``)."""
    return subparsers.add_parser(name, help=help, description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)


def add_scenario_file_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenario-file", action="append", default=[], metavar="TOML",
                        help="register the [scenario.NAME] tables of this TOML file first (repeatable)")


def load_scenario_files(args: argparse.Namespace) -> None:
    from fkn_bench.scenarios import load_scenarios

    for path in getattr(args, "scenario_file", []) or []:
        load_scenarios(path)


def check_minimum(args: argparse.Namespace, **minimum: int) -> None:
    """Usage error for the first integer option ``--NAME`` (``args.NAME``; None: not given) below
    its minimum, in the order given (0: "a non-negative integer", 1: "a positive integer")."""
    for name, low in minimum.items():
        value = getattr(args, name)
        if value is not None and value < low:
            kind = {0: "a non-negative integer", 1: "a positive integer"}.get(low, f"at least {low}")
            raise UsageError(f"--{name.replace('_', '-')} must be {kind} (got {value})")


def parse_value(text: str) -> Any:
    """A command-line value: None, a bool, an int, a float, a comma-separated list or a string."""
    lowered = text.strip().lower()
    if lowered in ("none", "null"):
        return None
    if lowered in ("true", "false"):
        return lowered == "true"
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    if "," in text:
        return [part.strip() for part in text.split(",") if part.strip()]
    return text


def parse_key_values(items: list[str], option: str) -> dict[str, Any]:
    """``KEY=VALUE`` strings to a dict (values through :func:`parse_value`)."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise UsageError(f"{option} expects KEY=VALUE (got {item!r})")
        out[key.strip()] = parse_value(value)
    return out


def output_directory(path: Any, option: str = "--out") -> Any:
    """``path`` as a directory that exists and can be written (created with its parents), or
    :class:`UsageError` in one line: a file in the way, a path that cannot be created, no write
    permission."""
    import os
    from pathlib import Path

    directory = Path(path)
    if directory.exists() and not directory.is_dir():
        raise UsageError(f"{option}: {directory} is a file, not a directory")
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"{option}: cannot create the directory {directory}: {exc.strerror or exc}") from None
    if not os.access(directory, os.W_OK | os.X_OK):
        raise UsageError(f"{option}: the directory {directory} is not writable")
    return directory


def default_leaderboards() -> Any:
    """The leaderboards directory the commands default to: ``./leaderboards`` when the current
    directory has one (a checkout's root), else the ``leaderboards`` of the fkn-bench checkout
    this package runs from (an editable or source install), so that README commands also work
    from other directories; ``./leaderboards`` when neither exists."""
    from pathlib import Path

    here = Path("leaderboards")
    if here.is_dir():
        return here
    import fkn_bench

    checkout = Path(fkn_bench.__file__).resolve().parents[1] / "leaderboards"
    return checkout if (checkout / "results").is_dir() else here
