"""Lazy re-exports for packages whose submodules import heavy libraries (torch, optuna, dask).

``fkn-bench --help`` must print within a second, so building the command line may import a
package (for a tuple of choices) without importing torch. A package lists what it re-exports and
from which submodule; :func:`lazy_exports` returns the module-level ``__getattr__`` and
``__dir__`` (PEP 562) that import a submodule on first access to one of its names.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["lazy_exports"]


def lazy_exports(package: str, exports: Mapping[str, str], namespace: dict[str, Any]) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for ``package`` (its ``__name__``): ``exports`` maps each
    re-exported name to the module that defines it (``".backends"`` for ``package.backends``, or
    an absolute module name); ``namespace`` is the package's ``globals()``, where a name is cached
    once imported."""

    def __getattr__(name: str) -> Any:
        submodule = exports.get(name)
        if submodule is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(submodule, package), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(exports))

    return __getattr__, __dir__
