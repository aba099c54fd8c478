"""Running one grid cell: filter a seed chunk with one estimator, time it, score it.

Steps (:func:`run_cell`): load the episodes of the chunk from the cell's source; take a copy of
the cell's estimator (built once, when the grid was resolved: every cell starts from the same
pristine estimator, on every backend); call ``estimate()`` once on the whole batch, then time a
short online run (the batched and online costs, :mod:`fkn_bench.harness.profiling`); score the
batch with :func:`fkn_bench.metrics.score_run`. Everything runs under
:func:`fkn_bench.runtime.torch_threads` (one torch thread by default), so results do not depend on
the process that runs the cell.

The rows' ``estimator`` column is the cell's label (:attr:`~fkn_bench.harness.grid.CellSpec.label`:
the name, with the options it ran with), so that rows of one estimator with and without options
stay apart.

An estimator that raises does not stop the grid: the cell is recorded as failed, with the error,
and each of its seeds counts as diverged.

An estimator with ``recorded = True`` (another program's output,
:class:`fkn_bench.estimators.external.ExternalEstimates`) is scored like any other, but its costs
are left empty (NaN: fkn-bench did not run it) and its ``report()`` goes into the cell's notes
(``external``).
"""

from __future__ import annotations

import copy
import traceback
from typing import Any

import numpy as np
import pandas as pd

from fkn_bench.estimators import Estimator
from fkn_bench.harness.grid import CellSpec
from fkn_bench.harness.profiling import measure
from fkn_bench.provenance import environment
from fkn_bench.harness.records import CellRecord
from fkn_bench.harness.rows import cost_rows, failure_rows, score_rows
from fkn_bench.metrics import score_run
from fkn_bench.runtime import torch_threads
from fkn_bench.types import ArrayF

__all__ = ["run_cell", "time_online"]


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


def _message(exc: BaseException) -> str:
    return "".join(traceback.format_exception_only(type(exc), exc)).strip()


def _record(spec: CellSpec, status: str, rows: list[pd.DataFrame], **fields: Any) -> CellRecord:
    return CellRecord(estimator=spec.estimator, scenario=spec.scenario, seeds=tuple(spec.seeds), key=spec.key(),
                      source=spec.source.describe(), status=status, rows=pd.concat(rows, ignore_index=True),
                      provenance=environment(), **fields)


def _failure(spec: CellSpec, exc: BaseException) -> CellRecord:
    detail = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    rows = [failure_rows(spec.label, spec.scenario, spec.seeds), cost_rows(spec.label, spec.scenario, spec.seeds, {})]
    return _record(spec, "failed", rows, error=_message(exc), notes={"traceback": detail})


def run_cell(spec: CellSpec) -> CellRecord:
    """Run ``spec`` (module docstring); never raises for estimator errors."""
    with torch_threads():
        episodes = spec.source.load(spec.seeds)
        dt = float(episodes.scenario.dt)
        try:
            if spec.resolved.estimator is None:
                raise RuntimeError(f"estimator {spec.estimator!r} is not available: {spec.resolved.error}")
            estimator = copy.deepcopy(spec.resolved.estimator)
            measurements = np.array(episodes.measurements)  # private copies: estimators get writable input
            valid = np.array(episodes.valid)
            stated = {"measurement_covariances": episodes.measurement_covariances} if getattr(
                estimator, "uses_measurement_covariances", False) else {}  # each step's R from its message
            with measure() as batched:
                estimates = estimator.estimate(measurements, valid, dt, **stated)
            scores = score_run(
                episodes.truth, estimates.means, dt, error_covariances=estimates.error_covariances,
                innovations=estimates.innovations, innovation_covariances=estimates.innovation_covariances,
                innovation_mask=estimates.innovation_mask, settings=spec.settings,
            )
        except Exception as exc:  # noqa: BLE001 - an estimator's failure is a result
            return _failure(spec, exc)
        notes: dict[str, Any] = {}
        defaults = estimates.extras.get("measurement_noise_defaults")
        if defaults is not None:  # measured steps without a usable stated covariance: the default R
            notes["measurement_noise_defaults"] = int(np.sum(defaults))
        trained_on = (getattr(estimator, "metadata", None) or {}).get("scenario")
        if trained_on:  # a learned or tuned estimator: the training set its parameters come from
            notes["trained_on"] = trained_on.get("name") if isinstance(trained_on, dict) else str(trained_on)
        recorded = getattr(estimator, "recorded", False) is True  # another program's output: nothing to time
        if recorded:
            notes["external"] = estimator.report()
        if getattr(estimator, "causal", True) is False:  # a smoother: it reads the whole episode, no online step
            notes["non_causal"] = True
            us_online = float("nan")
        elif recorded:
            us_online = float("nan")
        else:
            try:
                online_steps = min(spec.online_steps, episodes.n_steps)
                us_online = time_online(estimator, episodes.measurements[0, :online_steps], dt)
            except Exception as exc:  # noqa: BLE001 - timing only: keep the batch results
                us_online = float("nan")
                notes["online_error"] = _message(exc)
    cost = {
        "us_per_step_batched": 1e6 * batched.seconds / (episodes.batch_size * episodes.n_steps),
        "us_per_step_online": us_online,
        "peak_memory_mib": batched.peak_memory_mib,
    }
    if recorded:
        cost = {name: float("nan") for name in cost}
    rows = [score_rows(spec.label, spec.scenario, spec.seeds, scores),
            cost_rows(spec.label, spec.scenario, spec.seeds, cost)]
    return _record(spec, "ok", rows, nees=scores.nees_sums, nis=scores.nis_sums, notes=notes)
