"""Episodes and runs written into formats other tools read, and read back: Minari datasets of a
scenario's episodes (:mod:`~fkn_bench.exporters.datasets`, checked on reading by
:mod:`~fkn_bench.exporters.dataset_checks`; :class:`DatasetSource` feeds one to the harness) and
MCAP recordings of an estimator's run (:mod:`~fkn_bench.exporters.recording`; the MCAP format is
:mod:`fkn_bench.recordings`'). They sit above the estimators: a dataset stores a behaviour
estimator's actions, a recording an estimator's estimates.

Names are re-exported lazily (:mod:`fkn_bench.lazy`): importing the package imports neither
Minari nor the MCAP libraries until one of its names is used.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from fkn_bench.lazy import lazy_exports

_EXPORTS = {
    "DatasetError": ".datasets",
    "DatasetSource": ".datasets",
    "DatasetWarning": ".datasets",
    "read_dataset": ".datasets",
    "write_dataset": ".datasets",
    "record": ".recording",
}

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())

if TYPE_CHECKING:  # what the names are, for type checkers and IDEs
    from fkn_bench.exporters.datasets import DatasetError, DatasetSource, DatasetWarning, read_dataset, write_dataset
    from fkn_bench.exporters.recording import record

__all__ = ["DatasetError", "DatasetSource", "DatasetWarning", "read_dataset", "record", "write_dataset"]
