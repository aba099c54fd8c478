"""The benchmark harness: joins estimators, episodes and metrics into a grid of cells
(estimator x source x seed chunk), runs it on a backend, stores the results, and summarises them
(summaries over seeds, leaderboards, figures); each submodule's docstring says its part."""

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
from fkn_bench.harness.report import summary_text
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
    "summary_text",
]
