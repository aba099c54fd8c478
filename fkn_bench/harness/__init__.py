"""The benchmark harness: joins estimators, episodes and metrics into a grid of cells
(estimator x source x seed chunk), runs it on a backend, stores the cells, and summarises them over
seeds; beside the grid, the runs that tables and figures need (one seed kept whole, inertia-ratio
convergence, the shift and cross-scenario scores). Each submodule's docstring says its part;
tables, leaderboards and figures are drawn from these results by :mod:`fkn_bench.reporting`.

Names are re-exported lazily (:mod:`fkn_bench.lazy`): importing the package, e.g. for
:data:`BACKENDS`, imports no submodule until one of its names is used.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from fkn_bench.lazy import lazy_exports

_EXPORTS = {
    "BACKENDS": ".backends",
    "DaskBackend": ".backends",
    "LocalBackend": ".backends",
    "make_backend": ".backends",
    "run_cell": ".cell",
    "ResolvedEstimator": ".estimators",
    "Selection": ".estimators",
    "SelectionError": ".estimators",
    "resolve": ".estimators",
    "resolve_estimator": ".estimators",
    "select_estimators": ".estimators",
    "ONLINE_STEPS": ".grid",
    "SEED_CHUNK": ".grid",
    "CellSpec": ".grid",
    "build_grid": ".grid",
    "chunk_seeds": ".grid",
    "CellRecord": ".records",
    "Results": ".records",
    "COLUMNS": ".rows",
    "deterministic_rows": ".rows",
    "GridRun": ".runner",
    "run_grid": ".runner",
    "EpisodeSource": ".sources",
    "RecordingSource": ".sources",
    "SimulatedSource": ".sources",
    "CellChecksumError": ".store",
    "ForeignDirectoryError": ".store",
    "ResultStore": ".store",
    "StoreError": ".store",
    "PRIMARY_SCORE": ".summary",
    "summarize_pair": ".summary",
    "summarize_results": ".summary",
    "MetricSettings": "fkn_bench.metrics",
}

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())

if TYPE_CHECKING:  # what the names are, for type checkers and IDEs
    from fkn_bench.harness.backends import BACKENDS, DaskBackend, LocalBackend, make_backend
    from fkn_bench.harness.cell import run_cell
    from fkn_bench.harness.estimators import (
        ResolvedEstimator,
        Selection,
        SelectionError,
        resolve,
        resolve_estimator,
        select_estimators,
    )
    from fkn_bench.harness.grid import ONLINE_STEPS, SEED_CHUNK, CellSpec, build_grid, chunk_seeds
    from fkn_bench.harness.records import CellRecord, Results
    from fkn_bench.harness.rows import COLUMNS, deterministic_rows
    from fkn_bench.harness.runner import GridRun, run_grid
    from fkn_bench.harness.sources import EpisodeSource, RecordingSource, SimulatedSource
    from fkn_bench.harness.store import CellChecksumError, ForeignDirectoryError, ResultStore, StoreError
    from fkn_bench.harness.summary import PRIMARY_SCORE, summarize_pair, summarize_results
    from fkn_bench.metrics import MetricSettings

__all__ = [
    "BACKENDS",
    "COLUMNS",
    "CellChecksumError",
    "CellRecord",
    "CellSpec",
    "DaskBackend",
    "EpisodeSource",
    "ForeignDirectoryError",
    "GridRun",
    "LocalBackend",
    "MetricSettings",
    "ONLINE_STEPS",
    "PRIMARY_SCORE",
    "ResolvedEstimator",
    "ResultStore",
    "Results",
    "SEED_CHUNK",
    "RecordingSource",
    "Selection",
    "SelectionError",
    "SimulatedSource",
    "StoreError",
    "build_grid",
    "chunk_seeds",
    "deterministic_rows",
    "make_backend",
    "resolve",
    "resolve_estimator",
    "run_cell",
    "run_grid",
    "select_estimators",
    "summarize_pair",
    "summarize_results",
]
