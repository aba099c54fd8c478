"""fkn-bench: a benchmark suite for learned and adaptive Kalman filtering of a tumbling spacecraft.

Importing the package registers the Gymnasium environments (``AstrobeeTumble-v0``); the
scenarios, estimators and harness live in subpackages.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("fkn-bench")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

from fkn_bench.envs.registration import register_environments as _register_environments

_register_environments()

__all__ = ["__version__"]
