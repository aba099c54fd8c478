"""The benchmark harness: joins estimators, episodes and metrics into a grid of cells, runs it on
a backend, stores the results, and summarises them.

* :mod:`~fkn_bench.harness.sources`: where episodes come from (:class:`SimulatedSource`,
  :class:`RecordingSource`);
* :mod:`~fkn_bench.harness.grid`: cells (estimator x source x seed chunk);
* :mod:`~fkn_bench.harness.cell`: running and scoring one cell;
* :mod:`~fkn_bench.harness.backends`: local and Dask execution;
* :mod:`~fkn_bench.harness.store`, :mod:`~fkn_bench.harness.records`: result files and records;
* :mod:`~fkn_bench.harness.runner`: resumable grid runs;
* :mod:`~fkn_bench.harness.summary`, :mod:`~fkn_bench.harness.report`: summaries over seeds;
* :mod:`~fkn_bench.harness.leaderboard` and :mod:`~fkn_bench.harness.plots`: leaderboards and
  figures; :mod:`~fkn_bench.harness.reference`: the paper's quoted numbers.
"""

from fkn_bench.harness.backends import BACKENDS, DaskBackend, LocalBackend, make_backend
from fkn_bench.harness.cell import CellResult, run_cell
from fkn_bench.harness.estimators import (
    Availability,
    check_estimators,
    default_estimator,
    estimator_fingerprint,
    probe_estimator,
)
from fkn_bench.harness.grid import ONLINE_STEPS, SEED_CHUNK, CellSpec, build_grid, chunk_seeds
from fkn_bench.harness.records import CellRecord, Results, record_of
from fkn_bench.harness.report import summary_text
from fkn_bench.harness.rows import COLUMNS, deterministic_rows
from fkn_bench.harness.runner import GridRun, run_grid
from fkn_bench.harness.sources import EpisodeSource, RecordingSource, SimulatedSource
from fkn_bench.harness.store import ResultStore, StoreError
from fkn_bench.harness.summary import PRIMARY_SCORE, summarize_pair, summarize_results
from fkn_bench.metrics import MetricSettings

__all__ = [
    "Availability",
    "BACKENDS",
    "COLUMNS",
    "CellRecord",
    "CellResult",
    "CellSpec",
    "DaskBackend",
    "EpisodeSource",
    "GridRun",
    "LocalBackend",
    "MetricSettings",
    "ONLINE_STEPS",
    "PRIMARY_SCORE",
    "ResultStore",
    "Results",
    "SEED_CHUNK",
    "RecordingSource",
    "SimulatedSource",
    "StoreError",
    "build_grid",
    "check_estimators",
    "chunk_seeds",
    "default_estimator",
    "deterministic_rows",
    "estimator_fingerprint",
    "make_backend",
    "probe_estimator",
    "record_of",
    "run_cell",
    "run_grid",
    "summarize_pair",
    "summarize_results",
    "summary_text",
]
