"""Running a sweep: stages, worker processes that share one study, and the outputs.

:func:`run_sweep` creates (or resumes) the stage studies in the storage and runs each stage with
``workers`` processes (``spawn``ed; ``workers = 1`` runs in this process). Each worker loads the
study from the storage and runs its share of the trials still missing, so the study is shared
through the storage only: more processes (or machines, with an RDB URL) can join the same study
with the same command. ``trials`` is the number of trials a stage aims for, counting the trials
already in the study, so rerunning a finished sweep only rewrites the outputs.

Interrupted sweeps: ``out`` is locked while a sweep runs (:func:`fkn_bench.io.directory_lock`; a
second sweep into it is refused). A trial whose sweep was killed (optuna leaves it RUNNING) or
stopped by Ctrl-C is failed, not counted against ``trials`` and retried first with its parameters
(:func:`~fkn_bench.sweep.study.retry_interrupted`), and the samplers draw by trial index
(:class:`~fkn_bench.sweep.study.SweepSampler`): run again with the same command, a killed sweep
gives the trials, values and best configuration of the uninterrupted one (with one worker; with
more, which worker takes which trial is the scheduler's in any run). ``trials.csv`` lists an
interrupted trial as failed (``error`` "interrupted ..."), ``sweep.json`` counts it apart.

Outputs in ``out``:

* ``best.toml``: the best trial's full training configuration (``[<estimator>]`` table), for
  ``fkn-bench train --estimator <estimator> --config best.toml`` (FlexKalmanNet's also loads with
  ``FlexKalmanNetConfig.from_toml``);
* ``trials.csv``: every trial of every stage (stage, number, state, value, params, user
  attributes such as ``best_epoch``, ``epochs_run``, ``error`` and the ``process`` id that ran
  it, the last reported epoch);
* ``parallel_coordinates.png``: the completed trials' hyperparameters mapped to their validation
  RMSE (like the paper's sweep figure; :mod:`fkn_bench.sweep.figure`);
* ``sweep.json``: settings, the reduced grid of ``random-grid``, counts per state and the best
  trial.
"""

from __future__ import annotations

import errno
import json
import math
import multiprocessing
import sys
import warnings
from collections.abc import Callable
from contextlib import nullcontext
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import optuna
from optuna.trial import FrozenTrial, TrialState

from fkn_bench.io import DiskFullError, atomic_path, directory_lock, remove_temporaries, write_json_atomic, write_text_atomic
from fkn_bench.scenarios import Scenario
from fkn_bench.sweep.objective import CATCH, SweepTask, is_trainable, make_objective, trial_config
from fkn_bench.wording import worker_initializer
from fkn_bench.sweep.space import SearchSpace, check_sweep_options
from fkn_bench.sweep.study import (INTERRUPTED, completed, make_sampler, open_storage, reduced_grid, retry_interrupted,
                                   stage_names, storage_label, sweep_owner)

__all__ = ["SweepError", "SweepSettings", "SweepResult", "run_sweep", "write_toml", "shares"]

Log = Callable[[str], None]


class SweepError(RuntimeError):
    """A sweep that cannot go on (a worker crashed, no trial completed, a foreign study)."""


@dataclass(frozen=True)
class SweepSettings:
    """A sweep: the ``fkn-bench sweep`` options (``sampler``, ``trials``, ``grid_trials``, ``top_k``
    and ``seed`` as in a space's ``[sweep]`` table, see :mod:`fkn_bench.sweep.space`).
    ``grid_trials`` defaults to ``trials``, ``storage`` (a journal file path or an RDB URL) to
    ``out/study.journal`` and ``study_name`` to ``<estimator>-<scenario>``."""

    space: SearchSpace
    scenario: Scenario
    out: Path
    estimator: str
    sampler: str = "random-grid"
    trials: int = 20
    grid_trials: int | None = None
    top_k: int = 3
    workers: int = 1
    storage: str | None = None
    study_name: str | None = None
    seed: int = 0

    def __post_init__(self) -> None:
        check_sweep_options(vars(self))

    @property
    def storage_spec(self) -> str:
        return self.storage if self.storage is not None else str(Path(self.out) / "study.journal")

    @property
    def name(self) -> str:
        return self.study_name or f"{self.estimator}-{self.scenario.name}"


@dataclass
class SweepResult:
    """What a sweep produced."""

    best_value: float
    best_params: dict[str, Any]
    best_stage: str
    best_number: int
    best_config: Path
    trials_csv: Path
    figure: Path | None
    counts: dict[str, dict[str, int]]


@dataclass(frozen=True)
class _WorkerJob:
    settings: SweepSettings
    study_name: str
    stage: str
    worker: int
    n_trials: int
    grid: dict[str, list[Any]] | None
    verbose: bool


def shares(total: int, workers: int) -> list[int]:
    """``total`` trials split over ``workers`` as evenly as possible (zeros dropped)."""
    base, extra = divmod(max(total, 0), workers)
    return [n for n in (base + (1 if i < extra else 0) for i in range(workers)) if n > 0]


def _worker_main(job: _WorkerJob) -> None:
    """Run ``job.n_trials`` trials of a stage (in this process or a spawned one)."""
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    warnings.filterwarnings("ignore", category=optuna.exceptions.ExperimentalWarning)
    study = optuna.load_study(
        study_name=job.study_name,
        storage=open_storage(job.settings.storage_spec),
        sampler=make_sampler(job.stage, seed=job.settings.seed, worker=job.worker, grid=job.grid,
                             order=job.settings.space.names, owner=sweep_owner(job.settings.out)),
        pruner=job.settings.space.pruner.make(),
    )

    def report(study: optuna.Study, trial: FrozenTrial) -> None:
        if trial.state == TrialState.COMPLETE:
            outcome = f"validation RMSE {trial.value:.5g}"
        elif trial.state == TrialState.PRUNED:
            outcome = f"pruned after epoch {trial.last_step}"
        else:
            outcome = f"{trial.state.name.lower()}: {trial.user_attrs.get('error', '')}"
        params = ", ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}" for k, v in trial.params.items())
        print(f"[sweep] {job.stage} trial {trial.number} (worker {job.worker}): {outcome}; {params}",
              file=sys.stderr, flush=True)

    objective = make_objective(SweepTask(job.settings.estimator, job.settings.scenario, job.settings.space))

    def interruptible(trial: optuna.Trial) -> float:
        try:
            return objective(trial)
        except KeyboardInterrupt:  # (Ctrl-C, SIGTERM) optuna fails the trial; it is retried on resume
            trial.set_user_attr("error", "interrupted (Ctrl-C or SIGTERM); retried when the sweep runs again")
            trial.study._storage.set_trial_system_attr(trial._trial_id, INTERRUPTED, True)
            raise

    study.optimize(interruptible, n_trials=job.n_trials, catch=CATCH,
                   callbacks=[report] if job.verbose else [], gc_after_trial=False, show_progress_bar=False)


def _run_jobs(jobs: list[_WorkerJob], pool: ProcessPoolExecutor | None) -> None:
    """Run the jobs of a stage: in this process without a pool or with one job, else in ``pool``
    (``spawn``ed processes kept for every stage, importing torch once per process)."""
    if pool is None or len(jobs) <= 1:
        for job in jobs:
            _worker_main(job)
        return
    errors = []
    for job, future in [(job, pool.submit(_worker_main, job)) for job in jobs]:
        try:
            future.result()
        except BrokenProcessPool as exc:
            errors.append(f"worker {job.worker}: its process died ({exc})")
        except Exception as exc:  # noqa: BLE001 - reported together below
            errors.append(f"worker {job.worker}: {type(exc).__name__}: {exc}")
    if errors:
        raise SweepError("; ".join(errors))


def _prepare_study(storage: Any, name: str, settings: SweepSettings, stage: str) -> optuna.Study:
    study = optuna.create_study(storage=storage, study_name=name, direction="minimize", load_if_exists=True)
    identity = {
        "fkn_bench_space": settings.space.fingerprint(),
        "fkn_bench_estimator": settings.estimator,
        "fkn_bench_scenario": settings.scenario.config_hash(),
    }
    attrs = study.user_attrs
    for key, value in identity.items():
        if key in attrs and attrs[key] != value:
            raise SweepError(
                f"study {name!r} in {storage_label(settings.storage_spec)} was created with another "
                f"{key.removeprefix('fkn_bench_')} ({attrs[key]} vs {value}): choose another --study-name or --storage"
            )
    labels = {"fkn_bench_stage": stage, "fkn_bench_space_source": settings.space.source}
    for key, value in {**identity, **labels}.items():
        if key not in attrs:
            study.set_user_attr(key, value)
    return study


def _stage(settings: SweepSettings, stage: str, name: str, first: str, verbose: bool, log: Log,
           workers: ProcessPoolExecutor | None) -> dict[str, list[Any]] | None:
    """Run the trials still missing from ``stage`` (study ``name``; ``first``: the random stage's
    study of ``random-grid``); returns the stage's grid (None but for the grid stage)."""
    grid = settings.space.grid() if settings.sampler == "grid" else None
    target = settings.trials if grid is None else min(settings.trials, math.prod(len(v) for v in grid.values()))
    storage = open_storage(settings.storage_spec)
    study = _prepare_study(storage, name, settings, stage)
    if stage == "grid":
        stored = study.user_attrs.get("fkn_bench_grid")
        if settings.sampler == "random-grid":
            grid = stored
            if grid is None:
                random_study = optuna.load_study(study_name=first, storage=storage)
                try:
                    grid = reduced_grid(random_study.get_trials(deepcopy=False), settings.space,
                                        top_k=settings.top_k, budget=settings.grid_trials or settings.trials)
                except ValueError as exc:
                    raise SweepError(f"cannot derive the grid stage: {exc}") from None
            log(f"[sweep] reduced grid from the best {settings.top_k} random trials: {json.dumps(grid)}")
            target = math.prod(len(v) for v in grid.values())
        if stored is None:
            study.set_user_attr("fkn_bench_grid", grid)
        elif stored != grid:
            raise SweepError(f"study {name!r} already runs another grid ({stored}); choose another --study-name")
    interrupted = retry_interrupted(study, settings.out, own_storage=settings.storage is None)
    if interrupted:
        log(f"[sweep] stage {stage}: trial(s) {', '.join(map(str, interrupted))} interrupted (the sweep running them "
            "was killed or stopped): retried, not counted")
    remaining = target - sum(1 for t in study.get_trials(deepcopy=False)
                             if t.state != TrialState.WAITING and not t.system_attrs.get(INTERRUPTED))
    split = shares(remaining, settings.workers)
    log(f"[sweep] stage {stage} ({name}): {target} trials, {max(remaining, 0)} to run on {len(split)} worker(s)")
    _run_jobs([_WorkerJob(settings, name, stage, i, n, grid, verbose) for i, n in enumerate(split)], workers)
    return grid


def run_sweep(settings: SweepSettings, *, progress: bool = True, log: Log | None = None) -> SweepResult:
    """Run (or resume) the sweep and write its outputs (module docstring), holding the lock of
    ``settings.out`` (:func:`fkn_bench.io.directory_lock`: a second sweep into it raises
    :class:`~fkn_bench.io.LockedError`)."""
    with directory_lock(settings.out, "a sweep"):
        remove_temporaries(settings.out, recursive=False)
        try:
            return _run_sweep(settings, progress, log)
        except OSError as exc:  # the journal (an append-only log, not an atomic file) on a full disk
            if exc.errno in (errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC)) and "://" not in settings.storage_spec:
                raise DiskFullError(settings.storage_spec) from None
            raise


def _run_sweep(settings: SweepSettings, progress: bool, log: Log | None) -> SweepResult:
    say = log or (lambda message: None)
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    out = Path(settings.out)
    stages = stage_names(settings.name, settings.sampler)
    spawn = multiprocessing.get_context("spawn")
    initializer, initargs = worker_initializer()  # the command line's one-line warnings, in workers too
    with (ProcessPoolExecutor(settings.workers, mp_context=spawn, initializer=initializer, initargs=initargs)
          if settings.workers > 1 else nullcontext()) as workers:
        for stage, name in stages:
            grid = _stage(settings, stage, name, stages[0][1], progress, say, workers)
    result = write_outputs(settings, stages, grid)
    say(f"[sweep] best validation RMSE {result.best_value:.5g} ({result.best_stage} trial {result.best_number}); "
        f"outputs in {out}")
    return result


# ---------------------------------------------------------------------------------------------
# outputs
def _toml_value(value: Any) -> str:
    if isinstance(value, (bool, int, str)):
        return json.dumps(value)  # TOML's booleans, integers and basic strings are written as JSON's
    if isinstance(value, float):
        text = repr(value)  # nan, inf and -inf are TOML floats as they are
        return text if any(c in text for c in ".en") else text + ".0"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def write_toml(path: str | Path, values: dict[str, Any], *, table: str | None = None, header: str = "") -> Path:
    """Write a flat mapping of scalars and lists as TOML (``None`` values become comments: TOML
    has no null, and leaving the key out keeps the reader's default)."""
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    lines += ([""] if lines else []) + ([f"[{table}]"] if table else [])
    lines += [f"# {key}: None (the default when left out)" if value is None else f"{key} = {_toml_value(value)}"
              for key, value in values.items()]
    return write_text_atomic(path, "\n".join(lines) + "\n")


def parallel_coordinates(trials: list[FrozenTrial], space: SearchSpace, path: Path, title: str) -> Path | None:
    """Parallel-coordinates figure of the completed ``trials``
    (:func:`fkn_bench.sweep.figure.parallel_coordinates_figure`; None when there are none)."""
    from fkn_bench.plotting import save_png  # headless: matplotlib's Agg canvas
    from fkn_bench.sweep.figure import parallel_coordinates_figure

    done = completed(trials)
    if not done:
        return None
    return save_png(parallel_coordinates_figure(done, space, title=title), path, dpi=100)


def write_outputs(settings: SweepSettings, stages: list[tuple[str, str]], grid: dict[str, list[Any]] | None) -> SweepResult:
    """The outputs (module docstring) from the stage studies in the storage."""
    import pandas as pd

    out = Path(settings.out)
    storage = open_storage(settings.storage_spec)
    frames, everything, counts = [], [], {}
    best: tuple[FrozenTrial, str] | None = None
    for stage, name in stages:
        study = optuna.load_study(study_name=name, storage=storage)
        trials = study.get_trials(deepcopy=False)
        everything += trials
        counts[stage] = {state.name.lower(): sum(1 for t in trials if t.state == state and not t.system_attrs.get(INTERRUPTED))
                         for state in (TrialState.COMPLETE, TrialState.PRUNED, TrialState.FAIL, TrialState.RUNNING)}
        counts[stage]["interrupted"] = sum(1 for t in trials if t.system_attrs.get(INTERRUPTED))
        if trials:
            frame = study.trials_dataframe(attrs=("number", "value", "state", "params", "user_attrs", "duration"))
            frame.insert(0, "stage", stage)
            frame.insert(1, "study", name)
            frame["last_epoch_reported"] = frame["number"].map({t.number: t.last_step for t in trials})
            if "duration" in frame:
                frame["seconds"] = frame.pop("duration").dt.total_seconds()
            frames.append(frame)
        done = completed(trials)
        if done and (best is None or done[0].value < best[0].value):  # type: ignore[operator]
            best = (done[0], stage)
    frame = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()
    trials_csv = out / "trials.csv"
    with atomic_path(trials_csv, suffix=".csv") as tmp:
        frame.to_csv(tmp, index=False)
    if best is None:
        raise SweepError(f"no trial completed ({json.dumps(counts)}); see {trials_csv} for the errors")
    trial, stage = best
    config = trial_config(settings.estimator, settings.space, dict(trial.params)).to_dict()
    use = (f"use: fkn-bench train --estimator {settings.estimator} --scenario {settings.scenario.name} --config best.toml"
           if is_trainable(settings.estimator) else
           f"use: fkn-bench run --estimator {settings.estimator} "
           + " ".join(f"--estimator-option {k}={_option_text(v)}" for k, v in config.items()))
    header = (
        f"Best configuration of fkn-bench sweep study {settings.name!r} ({settings.sampler}), {stage} trial "
        f"{trial.number}\nvalidation 13-state RMSE {trial.value:.6g} on scenario {settings.scenario.name}\n"
        f"searched: {', '.join(f'{k} = {v!r}' for k, v in trial.params.items())}\n"
        + (f"fixed by the search space: {', '.join(f'{k} = {v!r}' for k, v in settings.space.fixed.items())}\n"
           "(the search's budget, not a recommendation: for a full training delete these lines below, or\n"
           f"override them, e.g. {' '.join(f'--set {k}=<value>' for k in settings.space.fixed)})\n"
           if settings.space.fixed and is_trainable(settings.estimator) else "")
        + use
    )
    best_config = write_toml(out / "best.toml", config, table=settings.estimator, header=header)
    figure = parallel_coordinates(
        everything, settings.space, out / "parallel_coordinates.png",
        f"{settings.name}: hyperparameters vs validation RMSE ({settings.sampler})",
    )
    write_json_atomic(out / "sweep.json", {
        "study_name": settings.name,
        "stages": [{"stage": s, "study": n} for s, n in stages],
        "storage": storage_label(settings.storage_spec),
        "estimator": settings.estimator,
        "scenario": settings.scenario.name,
        "scenario_config_hash": settings.scenario.config_hash(),
        **{key: getattr(settings, key) for key in ("sampler", "trials", "grid_trials", "top_k", "workers", "seed")},
        "space_source": settings.space.source,
        "space": settings.space.to_dict(),
        "grid": grid,
        "counts": counts,
        "best": {"stage": stage, "number": trial.number, "value": trial.value, "params": dict(trial.params),
                 "user_attrs": dict(trial.user_attrs)},
        "best_config": str(best_config),
    })
    return SweepResult(
        best_value=float(trial.value), best_params=dict(trial.params), best_stage=stage,  # type: ignore[arg-type]
        best_number=trial.number, best_config=best_config, trials_csv=trials_csv, figure=figure, counts=counts,
    )


def _option_text(value: Any) -> str:
    """``value`` as ``--estimator-option KEY=VALUE`` reads it (lists comma-separated)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return ",".join(_option_text(v) for v in value)
    return str(value)
