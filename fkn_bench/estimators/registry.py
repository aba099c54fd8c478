"""The estimator registry: names to factories, for the CLI, the harness and third parties.

Register your own estimator in one of two ways:

* in code, before running the harness::

      from fkn_bench.estimators import register_estimator
      register_estimator("my-filter", MyFilter.for_scenario, description="...")

* from an installed package, with an entry point in the group ``fkn_bench.estimators`` whose
  name is the estimator name and whose object is the factory::

      [project.entry-points."fkn_bench.estimators"]
      my-filter = "my_package.estimators:make_my_filter"

  or whose object is a module (no ``:name``) that registers its estimators with
  :func:`register_estimator` when imported (with descriptions and ``trainable=``). The built-in
  estimators are such entry points of fkn-bench itself (``pyproject.toml``); they load first, in
  the order of their entry-point names, then the other packages' entry points. A plugin that fails
  to load is left out with a warning; a plugin factory under a registered name is skipped.

A factory is called as ``factory(scenario=scenario, **options)`` where ``scenario`` is the
:class:`~fkn_bench.scenarios.Scenario` being evaluated (estimators that do not need it ignore
it) and returns an :class:`~fkn_bench.estimators.base.Estimator`. An estimator that can be
trained also passes ``trainable=`` (a :class:`~fkn_bench.training.Trainable`: how to read its
training options and which module to train); ``fkn-bench train`` and ``fkn-bench sweep`` then
train it through :func:`fkn_bench.training.fit`. An estimator that runs from committed parameter
files (``<name>-<family>.json``, and a network's ``.weights.pt`` beside it) passes
``params_package=`` (e.g. ``"my_package"``): the package whose ``params/`` folder holds them,
where :func:`fkn_bench.training.artifacts.artifact_path` looks for them and ``fkn-bench train
--write-artifact`` and ``fkn-bench sweep --write-artifact`` install them (ship the folder as the
package's data).

A saved estimator file (:meth:`Estimator.save <fkn_bench.estimators.base.Estimator.save>`,
read by :func:`load_estimator`) is data: the class it records must be one the registry has
loaded (:func:`estimator_classes`: the built-ins, the plugins, classes defined in code), never a
module the file names, and its configuration values are checked against the class's constructor.
"""

from __future__ import annotations

import importlib.metadata
import re
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fkn_bench.estimators.base import Estimator, EstimatorFileError, read_estimator_document
from fkn_bench.scenarios import Scenario

__all__ = [
    "EstimatorFactory",
    "EstimatorSpec",
    "UnknownEstimatorError",
    "register_estimator",
    "make_estimator",
    "estimator_names",
    "estimator_spec",
    "estimator_specs",
    "load_estimator",
    "estimator_classes",
    "ENTRY_POINT_GROUP",
]

ENTRY_POINT_GROUP = "fkn_bench.estimators"

_DISTRIBUTION = "fkn-bench"
"""The distribution whose entry points in :data:`ENTRY_POINT_GROUP` are the built-in estimators."""

EstimatorFactory = Callable[..., Estimator]


class UnknownEstimatorError(KeyError):
    """An estimator name that is not registered; the message lists the valid names."""

    def __str__(self) -> str:  # KeyError quotes its message; keep it readable
        return str(self.args[0])


@dataclass(frozen=True)
class EstimatorSpec:
    """A registered estimator: its name, factory, one-line description, for estimators that
    ``fkn-bench train`` and ``fkn-bench sweep`` can fit their
    :class:`~fkn_bench.training.Trainable` declaration (None: not trainable), and for estimators
    that run from committed parameter files the package whose ``params/`` folder holds them
    (``params_package``; None: none committed, ``parameters=PATH`` only)."""

    name: str
    factory: EstimatorFactory
    description: str = ""
    trainable: Any = None
    params_package: str | None = None


_REGISTRY: dict[str, EstimatorSpec] = {}
_LOADED = False


def register_estimator(
    name: str,
    factory: EstimatorFactory,
    *,
    description: str = "",
    trainable: Any = None,
    params_package: str | None = None,
    overwrite: bool = False,
) -> EstimatorSpec:
    """Register ``factory`` under ``name`` (see module docstring) and return its spec; a
    :class:`~fkn_bench.training.Trainable` ``trainable`` makes it trainable by
    :func:`fkn_bench.training.fit` (``fkn-bench train``, ``fkn-bench sweep``); ``params_package``
    (a dotted package name) holds its committed parameter files in ``params/``."""
    if not isinstance(name, str) or not name or any(c.isspace() for c in name):
        raise ValueError(f"estimator name must be a non-empty string without spaces (got {name!r})")
    if not callable(factory):
        raise TypeError(f"factory for estimator {name!r} must be callable")
    if trainable is not None and not (callable(getattr(trainable, "config", None)) and callable(getattr(trainable, "build", None))):
        raise TypeError(f"trainable of estimator {name!r} must be a fkn_bench.training.Trainable (callable config and build)")
    if params_package is not None and not (isinstance(params_package, str)
                                           and all(part.isidentifier() for part in params_package.split("."))):
        raise ValueError(f"params_package of estimator {name!r} must be a dotted package name (got {params_package!r})")
    if name in _REGISTRY and not overwrite:
        raise ValueError(f"estimator {name!r} is already registered (pass overwrite=True to replace it)")
    spec = EstimatorSpec(name, factory, description, trainable, params_package)
    _REGISTRY[name] = spec
    return spec


def _is_builtin(entry_point: importlib.metadata.EntryPoint) -> bool:
    """Whether ``entry_point`` is one of fkn-bench's own (a built-in estimator module)."""
    dist = getattr(entry_point, "dist", None)
    return dist is not None and re.sub(r"[-_.]+", "-", dist.name).lower() == _DISTRIBUTION


def _entry_points() -> list[importlib.metadata.EntryPoint]:
    """The entry points of :data:`ENTRY_POINT_GROUP`: fkn-bench's own by name, then the others as
    installed. Raises RuntimeError when fkn-bench's own are missing (its metadata is not
    installed)."""
    found = list(importlib.metadata.entry_points(group=ENTRY_POINT_GROUP))
    builtin = sorted((e for e in found if _is_builtin(e)), key=lambda e: e.name)
    if not builtin:
        raise RuntimeError(
            f"fkn-bench's built-in estimators are entry points '{ENTRY_POINT_GROUP}' of the installed package, and "
            "none is installed: install fkn-bench (pip install -e . in a checkout) and run it from that environment")
    return builtin + [e for e in found if not _is_builtin(e)]


def _ensure_loaded() -> None:
    global _LOADED
    if _LOADED:
        return
    entry_points = _entry_points()
    _LOADED = True
    for entry_point in entry_points:
        registers = entry_point.attr is None  # a module whose import registers its estimators
        if not registers and entry_point.name in _REGISTRY:
            continue
        try:
            factory = entry_point.load()
        except Exception as exc:  # a broken plugin must not break the built-ins (a broken built-in is an error)
            if _is_builtin(entry_point):
                raise
            warnings.warn(f"could not load estimator entry point {entry_point.name!r}: {exc}", stacklevel=2)
            continue
        if not registers:
            register_estimator(entry_point.name, factory, description=f"plugin {entry_point.value}")


def estimator_specs() -> list[EstimatorSpec]:
    """Registered estimators, built-ins first."""
    _ensure_loaded()
    return list(_REGISTRY.values())


def estimator_names() -> list[str]:
    """Registered estimator names, built-ins first."""
    return [spec.name for spec in estimator_specs()]


def estimator_spec(name: str) -> EstimatorSpec:
    """The registered spec of ``name`` (raises :class:`UnknownEstimatorError`)."""
    _ensure_loaded()
    try:
        return _REGISTRY[name]
    except KeyError:
        raise UnknownEstimatorError(f"unknown estimator {name!r}; valid estimators: {', '.join(_REGISTRY)}") from None


def make_estimator(name: str, /, *, scenario: Scenario | None = None, **options: Any) -> Estimator:
    """Build the estimator registered as ``name`` for ``scenario`` (options go to its factory,
    ``name=`` included: the registry name is positional-only so that it can be renamed)."""
    estimator = estimator_spec(name).factory(scenario=scenario, **options)
    if not isinstance(estimator, Estimator):
        raise TypeError(f"factory of estimator {name!r} returned {type(estimator).__name__}, not an Estimator")
    return estimator


def estimator_classes() -> dict[str, type[Estimator]]:
    """The estimator classes a saved estimator file may name, by ``"module:QualifiedName"``: every
    :class:`~fkn_bench.estimators.base.Estimator` subclass loaded once the registry is (the
    built-in estimators, the plugins of the entry-point group :data:`ENTRY_POINT_GROUP`, and any
    class defined or imported by code before the call)."""
    _ensure_loaded()
    found: dict[str, type[Estimator]] = {}
    stack: list[type] = [Estimator]
    while stack:
        for sub in stack.pop().__subclasses__():
            found.setdefault(f"{sub.__module__}:{sub.__qualname__}", sub)
            stack.append(sub)
    return found


def load_estimator(path: str | Path) -> Estimator:
    """Load an estimator saved with :meth:`Estimator.save` (its class is recorded in the file).

    The file is data: its ``class`` is looked up among :func:`estimator_classes` (no module that a
    file names is imported), and :meth:`Estimator.load <fkn_bench.estimators.base.Estimator.load>`
    checks its ``config`` against the annotations of the class's constructor
    (:mod:`fkn_bench.config_values`: a standard deviation is a finite JSON number, not ``true`` or
    ``"0.1"``) before the class builds from it. Every refusal is an
    :class:`~fkn_bench.estimators.base.EstimatorFileError` naming the file."""
    document = read_estimator_document(path)
    target = document.get("class")
    if not isinstance(target, str) or ":" not in target:
        raise EstimatorFileError(f"{path} does not record the estimator class ('class': 'module:Name')")
    known = estimator_classes()
    cls = known.get(target)
    if cls is None:
        raise EstimatorFileError(
            f"{path}: cannot import estimator class {target}: an estimator file may name only the class of a built-in "
            f"estimator or of an installed plugin (entry points '{ENTRY_POINT_GROUP}'), no module is imported for it, and "
            f"{target} is not an Estimator class of those; known: {', '.join(sorted(known))}")
    return cls.load(path)  # (which checks the config's values)
