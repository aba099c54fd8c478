"""How messages name options and how warnings reach a terminal.

The library's messages name an option the way their reader can act on it: a Python caller
reads ``repair=True`` (a keyword argument), a command-line user ``--repair`` (a flag).
:func:`option` spells an option for whoever is reading; the ``fkn-bench`` command line switches
to its spelling with :func:`cli_words` while a command runs.

Warnings: :func:`one_line_warnings` makes each warning one line (``fkn-bench run: warning:
...``) instead of Python's two (file, line number and category, then the source line), for the
command line and its worker processes.
"""

from __future__ import annotations

import sys
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Any, TextIO

__all__ = ["CLI_FLAGS", "cli_words", "install_one_line_warnings", "one_line_warnings", "option", "option_name", "worker_initializer"]

CLI_FLAGS: dict[str, str] = {
    "repair": "--repair",
    "quaternion_tolerance": "--quaternion-tolerance",
    "time_source": "--time-source",
    "truth_topic": "--truth-topic",
    "measurement_topic": "--measurement-topic",
    "dt": "--dt",
    "resume": "--resume",
    "out": "--out",
    "force": "--force",
}
"""Keyword arguments of the library and the ``fkn-bench`` flags that set them."""

_CLI_WORDS: ContextVar[bool] = ContextVar("fkn_bench_cli_words", default=False)


@contextmanager
def cli_words() -> Iterator[None]:
    """Within the block, :func:`option` spells options as command-line flags."""
    token = _CLI_WORDS.set(True)
    try:
        yield
    finally:
        _CLI_WORDS.reset(token)


def option_name(name: str) -> str:
    """``name`` (a keyword argument) as the reader knows it: ``quaternion_tolerance`` or, on the
    command line, ``--quaternion-tolerance``."""
    if _CLI_WORDS.get() and name in CLI_FLAGS:
        return CLI_FLAGS[name]
    return name


def option(name: str, value: Any = True) -> str:
    """An option set to ``value`` as the reader would write it: ``repair=True``,
    ``time_source='log'``, or on the command line ``--repair``, ``--time-source log``."""
    if _CLI_WORDS.get() and name in CLI_FLAGS:
        return CLI_FLAGS[name] if value is True else f"{CLI_FLAGS[name]} {value}"
    return f"{name}={value!r}"


def _one_line(message: Warning | str, category: type[Warning], prefix: str) -> str:
    text = " ".join(str(message).split())
    kind = "" if category in (UserWarning, RuntimeWarning) else f" ({category.__name__})"
    return f"{prefix}: warning{kind}: {text}\n"


def install_one_line_warnings(prefix: str = "fkn-bench", stream: TextIO | None = None) -> None:
    """Show every warning from now on as one line, ``PREFIX: warning: MESSAGE`` (the category
    named in brackets unless it is a plain UserWarning or RuntimeWarning), on ``stream`` (default:
    ``sys.stderr`` at the time of the warning). For worker processes, which have no block to
    leave."""

    def show(message: Warning | str, category: type[Warning], filename: str, lineno: int,
             file: TextIO | None = None, line: str | None = None) -> None:
        out = stream or file or sys.stderr
        try:
            out.write(_one_line(message, category, prefix))
        except (OSError, ValueError):  # a closed stream: nothing to warn on
            pass

    show.fkn_bench_prefix = prefix  # type: ignore[attr-defined]
    warnings.showwarning = show


def worker_initializer() -> tuple[Callable[..., None] | None, tuple[Any, ...]]:
    """``(initializer, initargs)`` for a process pool: spawned workers show warnings as this
    process does when it shows them one line each (else Python's display is left alone)."""
    prefix = getattr(warnings.showwarning, "fkn_bench_prefix", None)
    return (install_one_line_warnings, (prefix,)) if prefix else (None, ())


@contextmanager
def one_line_warnings(prefix: str = "fkn-bench") -> Iterator[None]:
    """Within the block, warnings are shown as :func:`install_one_line_warnings` shows them
    (the filters, e.g. show once per place, are unchanged); Python's display is restored after."""
    with warnings.catch_warnings():
        install_one_line_warnings(prefix)
        yield
