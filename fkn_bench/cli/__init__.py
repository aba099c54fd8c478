"""The ``fkn-bench`` command line. Each subcommand lives in its own module of this package and
exposes ``add_parser(subparsers)``, which registers the subcommand and sets ``handler``.

Exit codes: 0 success, 1 failure while running, 2 invalid usage (unknown estimator or scenario,
bad option values, unreadable input files, work over the memory limit) or an output that cannot be
written (a full disk: the path, the free space and the space needed; a directory locked by another
fkn-bench process), 130 interrupted (Ctrl-C, start-up included: one line, no traceback).
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

__all__ = ["main", "Interrupted", "UsageError", "usage_errors", "COMMANDS"]

COMMANDS: tuple[str, ...] = (
    "scenarios", "simulate", "run", "train", "bench", "leaderboard", "bound", "plot", "render", "record", "dataset",
    "reproduce", "sweep",
)
"""Subcommand modules, in the order ``--help`` lists them."""


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during a command that saved its work: the message says what was kept and how to go
    on (printed after "interrupted"; exit code 130)."""


class UsageError(Exception):
    """Invalid command-line input; printed without a traceback, exit code 2."""


@contextmanager
def usage_errors(*errors: type[BaseException]) -> Iterator[None]:
    """Re-raise ``errors`` raised in the block as :class:`UsageError` with the same message."""
    try:
        yield
    except errors as exc:
        raise UsageError(str(exc)) from None


def build_parser() -> argparse.ArgumentParser:
    from fkn_bench import __version__

    parser = argparse.ArgumentParser(
        prog="fkn-bench",
        description="Benchmark learned and adaptive Kalman filters on a tumbling Astrobee.",
    )
    parser.add_argument("--version", action="version", version=f"fkn-bench {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        importlib.import_module(f"fkn_bench.cli.{name}").add_parser(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``fkn-bench`` console script; returns the exit code."""
    import fkn_bench

    if signal.getsignal(signal.SIGINT) is fkn_bench._startup_interrupt:  # Ctrl-C is ours from here on
        signal.signal(signal.SIGINT, signal.default_int_handler)
    previous_term = _handle_sigterm()
    try:
        return _main(argv)
    finally:
        if previous_term is not None:
            signal.signal(signal.SIGTERM, previous_term)


def _terminated(signum: int, frame: object) -> None:
    raise KeyboardInterrupt("terminated")


def _handle_sigterm() -> object:
    """SIGTERM (``kill``) ends a command as Ctrl-C does, so that it stops its worker processes
    (killed outright, a run's process-pool workers were left orphaned); returns the previous
    handler to restore, or None where none was installed (not the main thread, or SIGTERM
    already handled by someone else)."""
    try:
        previous = signal.getsignal(signal.SIGTERM)
        if previous is not signal.SIG_DFL:
            return None
        signal.signal(signal.SIGTERM, _terminated)
        return previous
    except (ValueError, AttributeError):  # not the main thread; no SIGTERM on this platform
        return None


def _main(argv: Sequence[str] | None) -> int:
    try:
        from fkn_bench.io import LockedError, WriteError
        from fkn_bench.limits import SizeLimitError
        from fkn_bench.scenarios import ConfigError
        from fkn_bench.wording import cli_words, one_line_warnings

        parser = build_parser()
        args = parser.parse_args(argv)
    except KeyboardInterrupt:  # Ctrl-C while starting up: no traceback either
        print("fkn-bench: interrupted", file=sys.stderr)
        return 130
    try:
        with cli_words(), one_line_warnings(f"fkn-bench {args.command}"):  # flags, not keywords
            return int(args.handler(args) or 0)
    except (UsageError, ConfigError, SizeLimitError, WriteError, LockedError) as exc:
        print(f"fkn-bench {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        detail = f"; {exc}" if isinstance(exc, Interrupted) and str(exc) else ""
        print(f"fkn-bench {args.command}: interrupted{detail}", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `fkn-bench run | head`: the reader left, nothing to report
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # no second error when Python flushes stdout at exit
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
