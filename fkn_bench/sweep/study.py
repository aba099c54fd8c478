"""Studies, storages and samplers of a sweep, and the paper's two-stage search.

Storage (:func:`open_storage`): a path is an optuna journal file
(``JournalStorage(JournalFileBackend(path))``, the default ``OUT/study.journal``): an append-only
log that several processes on one machine (or on a shared file system) write safely; anything
with ``://`` is an SQLAlchemy URL for optuna's ``RDBStorage`` (``sqlite:///sweep.db``,
``postgresql://user:password@host/db`` with a PostgreSQL driver installed), which processes on
several machines share.

Samplers (:func:`make_sampler`): ``random`` (``RandomSampler``), ``tpe`` (``TPESampler``),
``grid`` (``GridSampler`` over the space's grid) and ``random-grid``, the paper's method
(section 4.2): "first, a random search to narrow down a reduced hyperparameter space, followed by
a grid search". Its two stages are two studies, ``NAME.random`` and ``NAME.grid``, in the same
storage. The reduced grid is derived from the random stage by :func:`reduced_grid`:

1. rank the random stage's completed trials by validation RMSE and keep the best ``top_k``;
2. each knob's candidates are the values these trials used (floats rounded to 3 significant
   digits), deduplicated, ordered by the rank of the best trial that used them;
3. while the grid (the product of the candidate counts) exceeds ``budget`` points, drop the
   candidate, among knobs with more than one, whose best trial ranks lowest. At worst this leaves
   the best trial's own configuration (one point).

The derived grid is stored in the grid study's user attributes, so a later invocation (or another
machine sharing the storage) runs the same grid rather than deriving a new one.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import optuna
from optuna.storages import BaseStorage, JournalStorage, RDBStorage
from optuna.storages.journal import JournalFileBackend
from optuna.trial import FrozenTrial, TrialState

from fkn_bench.sweep.space import SearchSpace

__all__ = [
    "open_storage",
    "storage_label",
    "make_sampler",
    "stage_names",
    "reduced_grid",
    "completed",
]

def storage_label(spec: str | Path) -> str:
    """How a storage is named in outputs (an RDB URL without its password)."""
    text = str(spec)
    if "://" not in text:
        return text
    from sqlalchemy.engine import make_url  # optuna's RDBStorage runs on SQLAlchemy

    return make_url(text).render_as_string(hide_password=True)


def open_storage(spec: str | Path) -> BaseStorage:
    """A journal-file storage for a path, an RDB storage for a URL (module docstring)."""
    text = str(spec)
    if "://" in text:
        return RDBStorage(text)
    Path(text).parent.mkdir(parents=True, exist_ok=True)
    return JournalStorage(JournalFileBackend(text))


def stage_names(study_name: str, sampler: str) -> list[tuple[str, str]]:
    """``(stage, study name)`` pairs: two for ``random-grid``, one otherwise."""
    if sampler == "random-grid":
        return [(stage, f"{study_name}.{stage}") for stage in ("random", "grid")]
    return [(sampler, study_name)]


def make_sampler(
    kind: str, *, seed: int, worker: int = 0, grid: dict[str, list[Any]] | None = None
) -> optuna.samplers.BaseSampler:
    """The sampler of a stage for worker ``worker`` (random and TPE samplers get ``seed + worker``
    so that parallel workers draw different points; the grid sampler gets the same seed in every
    worker, as optuna recommends, and picks grid points by trial number)."""
    if kind in ("random", "tpe"):
        sampler = optuna.samplers.RandomSampler if kind == "random" else optuna.samplers.TPESampler
        return sampler(seed=seed + worker)
    if kind == "grid":
        if grid is None:
            raise ValueError("the grid sampler needs a grid")
        return optuna.samplers.GridSampler(grid, seed=seed)
    raise ValueError(f"unknown sampler {kind!r}")


def completed(trials: Sequence[FrozenTrial]) -> list[FrozenTrial]:
    """Completed trials with a finite value, best first (ties: lower trial number first)."""
    done = [t for t in trials if t.state == TrialState.COMPLETE and t.value is not None and math.isfinite(t.value)]
    return sorted(done, key=lambda t: (t.value, t.number))


def _round(value: Any, knob: Any) -> Any:
    if knob.kind != "float" or knob.step is not None:
        return value
    rounded = float(f"{float(value):.3g}")
    return min(max(rounded, float(knob.low)), float(knob.high))


def reduced_grid(trials: Sequence[FrozenTrial], space: SearchSpace, *, top_k: int, budget: int) -> dict[str, list[Any]]:
    """The grid of the second stage of ``random-grid`` (module docstring, steps 1-3)."""
    if top_k < 1 or budget < 1:
        raise ValueError(f"top_k and budget must be >= 1 (got {top_k}, {budget})")
    best = completed(trials)[:top_k]
    if not best:
        raise ValueError("the random stage has no completed trial to derive a grid from")
    candidates: dict[str, list[tuple[Any, int]]] = {}
    for knob in space.knobs:
        first: dict[str, tuple[Any, int]] = {}
        for rank, trial in enumerate(best):
            value = _round(trial.params[knob.name], knob)
            first.setdefault(repr(value), (value, rank))
        candidates[knob.name] = list(first.values())
    while math.prod(len(v) for v in candidates.values()) > budget:
        shrinkable = [name for name, values in candidates.items() if len(values) > 1]
        candidates[max(shrinkable, key=lambda name: candidates[name][-1][1])].pop()
    grid = {name: [v for v, _ in values] for name, values in candidates.items()}
    return {k.name: grid[k.name] if k.kind == "categorical" else sorted(grid[k.name]) for k in space.knobs}
