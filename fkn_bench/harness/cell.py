"""Running one grid cell: filter a seed chunk with one estimator, time it, score it.

Steps (:func:`run_cell`): load the episodes of the chunk from the cell's source; build the
estimator with ``make_estimator(name, scenario=...)``; call ``estimate()`` once on the whole batch
(timed, with peak memory: the batched cost); time a short online run (``reset`` and ``step`` over
the first ``online_steps`` steps of the chunk's first sequence: the online cost); score the batch
with :func:`fkn_bench.metrics.score_run`. Everything runs under
:func:`fkn_bench.runtime.torch_threads` (one torch thread by default), so results do not depend on
the process that runs the cell.

An estimator that raises does not stop the grid: the cell is recorded as failed, with the error,
and each of its seeds counts as diverged.
"""

from __future__ import annotations

import traceback
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from fkn_bench.estimators import Estimator, make_estimator
from fkn_bench.harness.grid import CellSpec
from fkn_bench.harness.profiling import measure
from fkn_bench.provenance import environment
from fkn_bench.harness.rows import cost_rows, failure_rows, score_rows
from fkn_bench.metrics import StatisticSums, score_run
from fkn_bench.runtime import torch_threads
from fkn_bench.types import ArrayF

__all__ = ["CellResult", "run_cell", "time_online"]


@dataclass(frozen=True, eq=False)
class CellResult:
    """The outcome of one cell.

    Attributes:
        spec: the cell.
        rows: tidy rows (:mod:`fkn_bench.harness.rows`), cost rows included.
        nees, nis: per-step sums over the cell's runs for the Monte Carlo averages (None when
            the estimator reports no covariances / innovations, or failed).
        status: ``"ok"`` or ``"failed"``.
        error: the exception (type, message and traceback) of a failed cell.
        notes: extra facts (e.g. an online run that failed while the batch succeeded).
        provenance: :func:`fkn_bench.provenance.environment` of the process that ran it.
    """

    spec: CellSpec
    rows: pd.DataFrame
    nees: StatisticSums | None
    nis: StatisticSums | None
    status: str
    error: str | None = None
    notes: dict[str, Any] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)


def time_online(estimator: Estimator, measurements: ArrayF, dt: float, *, passes: int = 2) -> float:
    """Microseconds per ``step()`` of ``reset(dt=dt)`` then one step per row of
    ``measurements (n, 7)`` (NaN rows are missing measurements): the fastest of ``passes`` timed
    passes, so that one-time costs of a first call (lazy imports, caches filled on the first
    ``reset``) are not counted as the per-step cost."""
    observations = [np.array(row) for row in measurements]
    best = float("inf")
    for _ in range(max(int(passes), 1)):
        with measure(memory=False) as timing:
            estimator.reset(dt=dt)
            for observation in observations:
                estimator.step(observation)
        best = min(best, timing.seconds)
    return 1e6 * best / max(len(observations), 1)


def _failure(spec: CellSpec, exc: BaseException) -> CellResult:
    message = "".join(traceback.format_exception_only(type(exc), exc)).strip()
    detail = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    rows = pd.concat(
        [
            failure_rows(spec.estimator, spec.scenario, spec.seeds),
            cost_rows(spec.estimator, spec.scenario, spec.seeds, {}),
        ],
        ignore_index=True,
    )
    return CellResult(spec, rows, None, None, "failed", error=message, notes={"traceback": detail},
                      provenance=environment())


def run_cell(spec: CellSpec) -> CellResult:
    """Run ``spec`` (module docstring); never raises for estimator errors."""
    with torch_threads():
        episodes = spec.source.load(spec.seeds)
        dt = float(episodes.scenario.dt)
        try:
            estimator = make_estimator(spec.estimator, scenario=spec.source.scenario, **dict(spec.estimator_options))
            measurements = np.array(episodes.measurements)  # private copies: estimators get writable input
            valid = np.array(episodes.valid)
            with measure() as batched:
                estimates = estimator.estimate(measurements, valid, dt)
            scores = score_run(
                episodes.truth,
                estimates.means,
                dt,
                error_covariances=estimates.error_covariances,
                innovations=estimates.innovations,
                innovation_covariances=estimates.innovation_covariances,
                innovation_mask=estimates.innovation_mask,
                settings=spec.settings,
            )
        except Exception as exc:  # noqa: BLE001 - an estimator's failure is a result
            return _failure(spec, exc)
        notes: dict[str, Any] = {}
        try:
            online_steps = min(spec.online_steps, episodes.n_steps)
            us_online = time_online(estimator, episodes.measurements[0, :online_steps], dt)
        except Exception as exc:  # noqa: BLE001 - timing only: keep the batch results
            us_online = float("nan")
            notes["online_error"] = "".join(traceback.format_exception_only(type(exc), exc)).strip()
    cost = {
        "us_per_step_batched": 1e6 * batched.seconds / (episodes.batch_size * episodes.n_steps),
        "us_per_step_online": us_online,
        "peak_memory_mib": batched.peak_memory_mib,
    }
    rows = pd.concat(
        [
            score_rows(spec.estimator, spec.scenario, spec.seeds, scores),
            cost_rows(spec.estimator, spec.scenario, spec.seeds, cost),
        ],
        ignore_index=True,
    )
    return CellResult(spec, rows, scores.nees_sums, scores.nis_sums, "ok", notes=notes, provenance=environment())
