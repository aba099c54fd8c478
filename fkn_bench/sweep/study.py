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

import copy
import math
import socket
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import optuna
from optuna.storages import BaseStorage, JournalStorage, RDBStorage
from optuna.storages.journal import JournalFileBackend
from optuna.trial import FrozenTrial, TrialState

from fkn_bench.sweep.space import SearchSpace

__all__ = [
    "INTERRUPTED",
    "SweepSampler",
    "retry_interrupted",
    "sweep_owner",
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


INTERRUPTED = "fkn_bench_interrupted"
"""System attribute of a trial whose sweep was killed or interrupted while it ran (it is failed,
not counted, and retried: :func:`retry_interrupted`)."""
RETRY_OF = "fkn_bench_retry_of"
"""System attribute of the retry of an interrupted trial: the interrupted trial's number."""
PRESET = "fkn_bench_preset"
"""System attribute of a retry: the parameters it took from the interrupted trial (not drawn)."""
WORKER = "fkn_bench_worker"
"""System attribute: the worker (``0 .. workers - 1``) whose sampler drew the trial."""
OWNER = "fkn_bench_owner"
"""System attribute: ``{"host", "directory"}`` of the sweep that ran the trial (its locked output
directory: :func:`sweep_owner`)."""


def sweep_owner(out: str | Path) -> dict[str, str]:
    """What a trial records of the sweep that runs it: this machine and the sweep's output
    directory, which that sweep holds locked (:func:`fkn_bench.io.directory_lock`) while it runs."""
    return {"host": socket.gethostname(), "directory": str(Path(out).resolve())}


def _interrupted_before(trials: Sequence[FrozenTrial], number: int) -> int:
    return sum(1 for t in trials if t.number < number and t.system_attrs.get(INTERRUPTED))


class SweepSampler(optuna.samplers.BaseSampler):
    """A stage's sampler whose draws do not depend on the process that makes them, so that a sweep
    killed and run again gives the trials an uninterrupted sweep gives.

    A trial's *draw index* is its number less the interrupted trials before it (their retries take
    their place). ``random`` (one ``RandomSampler(seed + worker)`` per worker, optuna's own) replays
    the draws of the worker's earlier trials before drawing, so its sequence continues across
    invocations (a second invocation does not repeat the first one's points); ``tpe`` seeds a
    fresh ``TPESampler`` with ``(seed, draw index)`` for every trial; ``grid`` (optuna's
    ``GridSampler``, the same seed in every worker) assigns grid point ``draw index`` while any is
    left. Every trial records its worker and :func:`sweep_owner` (``owner``)."""

    def __init__(self, kind: str, *, seed: int, worker: int = 0, grid: dict[str, list[Any]] | None = None,
                 order: Sequence[str] = (), owner: dict[str, str] | None = None) -> None:
        if kind not in ("random", "tpe", "grid"):
            raise ValueError(f"unknown sampler {kind!r}")
        if kind == "grid" and grid is None:
            raise ValueError("the grid sampler needs a grid")
        self.kind, self.seed, self.worker, self.order, self.owner = kind, seed, worker, tuple(order), owner
        self._grid = optuna.samplers.GridSampler(grid, seed=seed) if kind == "grid" else None  # type: ignore[arg-type]
        self._inner: optuna.samplers.BaseSampler = self._grid or optuna.samplers.RandomSampler(seed=seed + worker)

    def _replayed(self, trials: Sequence[FrozenTrial], number: int) -> optuna.samplers.RandomSampler:
        """``RandomSampler(seed + worker)`` after the draws of this worker's trials before ``number``
        (each parameter it drew, in the space's order: not those fixed by ``enqueue_trial`` or
        taken by a retry)."""
        sampler = optuna.samplers.RandomSampler(seed=self.seed + self.worker)
        for t in sorted(trials, key=lambda t: t.number):
            if t.number >= number or t.system_attrs.get(WORKER, 0) != self.worker:
                continue
            given = set(t.system_attrs.get("fixed_params", {})) | set(t.system_attrs.get(PRESET, ()))
            for name in (*self.order, *sorted(set(t.distributions) - set(self.order))):
                if name in t.distributions and name not in given and not t.distributions[name].single():
                    sampler.sample_independent(None, t, name, t.distributions[name])  # type: ignore[arg-type]
        return sampler

    def before_trial(self, study: optuna.Study, trial: FrozenTrial) -> None:
        storage = study._storage
        storage.set_trial_system_attr(trial._trial_id, WORKER, self.worker)
        if self.owner is not None:
            storage.set_trial_system_attr(trial._trial_id, OWNER, self.owner)
        trials = storage.get_all_trials(study._study_id, deepcopy=False)
        index = trial.number - _interrupted_before(trials, trial.number)
        if self.kind == "random":
            self._inner = self._replayed(trials, trial.number)
        elif self.kind == "tpe":
            self._inner = optuna.samplers.TPESampler(seed=int(np.random.SeedSequence([self.seed, index]).generate_state(1)[0]))
        else:  # optuna's GridSampler assigns grid point `number` while there is one: give it the index
            trial = copy.copy(trial)
            trial.number = index
        self._inner.before_trial(study, trial)

    def infer_relative_search_space(self, study: optuna.Study, trial: FrozenTrial) -> dict[str, Any]:
        return self._inner.infer_relative_search_space(study, trial)

    def sample_relative(self, study: optuna.Study, trial: FrozenTrial, search_space: dict[str, Any]) -> dict[str, Any]:
        return self._inner.sample_relative(study, trial, search_space)

    def sample_independent(self, study: optuna.Study, trial: FrozenTrial, param_name: str, param_distribution: Any) -> Any:
        return self._inner.sample_independent(study, trial, param_name, param_distribution)

    def after_trial(self, study: optuna.Study, trial: FrozenTrial, state: TrialState, values: Sequence[float] | None) -> None:
        self._inner.after_trial(study, trial, state, values)


def make_sampler(
    kind: str, *, seed: int, worker: int = 0, grid: dict[str, list[Any]] | None = None, order: Sequence[str] = (),
    owner: dict[str, str] | None = None,
) -> optuna.samplers.BaseSampler:
    """The sampler of a stage for worker ``worker``: a :class:`SweepSampler` (random and TPE draws
    differ between parallel workers; the grid sampler gets the same seed in every worker, as optuna
    recommends). ``order``: the space's knob names, in the order a trial suggests them."""
    return SweepSampler(kind, seed=seed, worker=worker, grid=grid, order=order, owner=owner)


def retry_interrupted(study: optuna.Study, out: str | Path, *, own_storage: bool) -> list[int]:
    """Fail the trials of ``study`` whose sweep is gone while they ran, and enqueue a retry of
    every interrupted trial without one; returns the numbers of the trials it failed or retried.

    A trial left RUNNING is the sweep's that ran it (:data:`OWNER`); that sweep is gone when its
    output directory is ``out`` (whose lock the caller holds), lies on this machine and can be
    locked or no longer exists. A trial of another machine's live sweep is left alone. One without
    an owner (recorded by an earlier fkn-bench) counts as gone when the storage is this sweep's own
    (``own_storage``: the journal in ``out``). A trial interrupted by Ctrl-C or SIGTERM was failed
    by optuna and marked :data:`INTERRUPTED` by the objective. The retry is a waiting trial with the
    interrupted one's parameters and grid point (:data:`RETRY_OF`, :data:`PRESET`): it runs next, so
    the sweep's trials, values and best configuration are the uninterrupted sweep's (only
    ``trials.csv`` also lists the interrupted trial, failed, with ``error`` "interrupted ...")."""
    storage = study._storage
    trials = study.get_trials(deepcopy=False)
    retried = {t.system_attrs.get(RETRY_OF) for t in trials}
    found = []
    for t in trials:
        stale = t.state == TrialState.RUNNING and _owner_is_gone(t.system_attrs.get(OWNER), out, own_storage)
        unretried = t.system_attrs.get(INTERRUPTED) and t.state.is_finished() and t.number not in retried
        if not (stale or unretried):
            continue
        found.append(t.number)
        if t.number not in retried:
            inherited = {k: t.system_attrs[k] for k in ("fixed_params", "grid_id", "search_space") if k in t.system_attrs}
            study.add_trial(optuna.trial.create_trial(
                state=TrialState.WAITING, params=t.params, distributions=t.distributions,
                system_attrs={**inherited, RETRY_OF: t.number, PRESET: sorted(t.params)},
            ))
        if stale:
            storage.set_trial_user_attr(t._trial_id, "error", "interrupted: the sweep running it was killed; retried")
            storage.set_trial_system_attr(t._trial_id, INTERRUPTED, True)
            storage.set_trial_state_values(t._trial_id, TrialState.FAIL)
    return found


def _owner_is_gone(owner: Any, out: str | Path, own_storage: bool) -> bool:
    """Whether the sweep ``owner`` (:func:`sweep_owner`) of a RUNNING trial no longer runs (see
    :func:`retry_interrupted`)."""
    from fkn_bench.io import LockedError, directory_lock

    if not isinstance(owner, dict):
        return own_storage
    if owner.get("host") != socket.gethostname():
        return False
    directory = Path(str(owner.get("directory")))
    if directory == Path(out).resolve() or not directory.is_dir():
        return True
    try:
        with directory_lock(directory):
            return True
    except LockedError:
        return False


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
