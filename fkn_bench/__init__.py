"""fkn-bench: a benchmark suite for learned and adaptive Kalman filtering of a tumbling spacecraft.

Importing the package registers the Gymnasium environments (``AstrobeeTumble-v0``); the
scenarios, estimators and harness live in subpackages.
"""

from __future__ import annotations


def _quiet_interrupt_while_the_command_starts() -> None:
    """In the ``fkn-bench`` console script, Ctrl-C during start-up (this package's imports, before
    :func:`fkn_bench.cli.main` takes over) ends the command with one line and status 130 instead
    of a traceback; ``main`` restores Python's handler first thing."""
    import os
    import signal
    import sys

    program = os.path.splitext(os.path.basename(sys.argv[0]))[0] if sys.argv and sys.argv[0] else ""
    if program != "fkn-bench" or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        return  # not the command, or someone else's handler (an embedding process): leave it
    try:
        signal.signal(signal.SIGINT, _startup_interrupt)
    except ValueError:  # not the main thread
        pass


def _startup_interrupt(signum: int, frame: object) -> None:
    """SIGINT handler of the command's start-up (see above): one line, status 130."""
    import os

    os.write(2, b"fkn-bench: interrupted\n")
    os._exit(130)


_quiet_interrupt_while_the_command_starts()

from importlib.metadata import PackageNotFoundError, version  # noqa: E402

try:
    __version__ = version("fkn-bench")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

from fkn_bench.envs.registration import register_environments as _register_environments

_register_environments()

__all__ = ["__version__"]
