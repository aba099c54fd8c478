"""Stored bounds: the posterior Cramér-Rao bound (:mod:`fkn_bench.metrics.bound`) of each simulated
scenario of a results directory, kept beside its cells so that leaderboards stay a pure function
of stored results.

Layout under the results root::

    bounds/<scenario>.json    the bound of the scenario's scored episodes (per seed) and its key

The key is what makes a bound belong to the results: the source key of the cells
(``simulated:<scenario>:<configuration hash>:<split>``), their ``cut``, and the seeds (every seed
any estimator was scored on in that scenario). :func:`store_bounds` computes the bound of every
simulated scenario whose stored bound is missing or has another key; :func:`read_bounds` returns
those whose key matches the results. Recordings have no stated prior and get no bound. Files are
written atomically (:mod:`fkn_bench.io`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from fkn_bench.harness.grid import path_name
from fkn_bench.harness.records import Results
from fkn_bench.io import read_json, write_json_atomic

__all__ = ["BOUNDS_DIR", "BOUND_FORMAT", "bound_key", "bound_path", "store_bounds", "read_bounds", "bound_document"]

BOUNDS_DIR = "bounds"
BOUND_FORMAT = "fkn-bench-bound"
BOUND_FORMAT_VERSION = 2
"""Raised when the bound's computation changes, so that stored bounds are recomputed (2: a free
tumble of a time-split scenario starts at the split, :mod:`fkn_bench.metrics.bound`)."""


def bound_path(root: str | Path, scenario: str) -> Path:
    """``<root>/bounds/<scenario>.json`` (the name encoded by :func:`~fkn_bench.harness.grid.path_name`)."""
    return Path(root) / BOUNDS_DIR / f"{path_name(scenario)}.json"


def bound_key(results: Results, scenario: str) -> dict[str, Any] | None:
    """What the bound of ``scenario``'s results must have been computed for (module docstring);
    None when the scenario's episodes are not simulated (a recording)."""
    records = [r for r in results.records if r.scenario == scenario]
    if not records or records[0].source.get("kind") != "simulated":
        return None
    seeds = sorted({s for r in records for s in r.seeds})
    return {"format": BOUND_FORMAT, "format_version": BOUND_FORMAT_VERSION, "source": records[0].key["source"],
            "cut": int(results.settings(scenario).cut), "seeds": seeds}


def bound_document(results: Results, scenario: str) -> dict[str, Any] | None:
    """The bound of ``scenario``'s results, computed now: ``{"key": ..., "bound": Bound.to_dict()}``
    (None for a recording)."""
    from fkn_bench.metrics.bound import posterior_bound
    from fkn_bench.scenarios import Scenario

    key = bound_key(results, scenario)
    if key is None:
        return None
    source = results.source(scenario)
    bound = posterior_bound(Scenario.from_dict(source["config"]), key["seeds"], split=source["split"], cut=key["cut"])
    return {"key": key, "bound": bound.to_dict()}


def store_bounds(root: str | Path, results: Results, *, force: bool = False,
                 progress: Callable[[str], None] | None = None) -> list[str]:
    """Compute and write the bound of every simulated scenario of ``results`` whose stored bound
    is missing or belongs to other results (every one with ``force``); returns the scenarios
    written."""
    stored = read_bounds(root, results) if not force else {}
    written = []
    for scenario in results.scenarios():
        if scenario in stored or bound_key(results, scenario) is None:
            continue
        if progress is not None:
            progress(scenario)
        document = bound_document(results, scenario)
        write_json_atomic(bound_path(root, scenario), document)
        written.append(scenario)
    return written


def read_bounds(root: str | Path, results: Results) -> dict[str, dict[str, Any]]:
    """``{scenario: Bound.to_dict()}`` of the stored bounds whose key matches ``results``
    (module docstring); a missing, unreadable or stale bound is left out, and so is the bound of
    a scenario whose records mix metric settings (:meth:`Results.settings` refuses them)."""
    out = {}
    for scenario in results.scenarios():
        path = bound_path(root, scenario)
        if not path.is_file():
            continue
        try:
            document = read_json(path)
        except (OSError, ValueError):
            continue
        try:
            key = bound_key(results, scenario)
        except ValueError:  # records that mix metric settings: no bound belongs to them
            continue
        if isinstance(document, dict) and document.get("key") == key and isinstance(document.get("bound"), dict):
            out[scenario] = document["bound"]
    return out
