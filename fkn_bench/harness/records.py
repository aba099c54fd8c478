"""Cell records (a cell's outcome in plain data: no estimator, no source object) and their
collection (:class:`Results`): what the store reads and writes and what summaries, leaderboards
and plots consume.

Results are grouped by the estimator's *label* (:func:`fkn_bench.harness.grid.estimator_label`:
its name, with the factory options it ran with, ``"manual-ekf (gate=0.5)"``), so that a run with
options is a row of its own; the tidy rows' ``estimator`` column holds the label too. Records of
one scenario that were scored on different data or with different settings (split, scenario
configuration, ``cut``, ...) cannot be ranked together: :meth:`Results.check_comparable` refuses
them in one line.
"""

from __future__ import annotations

import functools
import json
import operator
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import pandas as pd

from fkn_bench.harness.grid import estimator_label
from fkn_bench.harness.rows import COLUMNS, sort_rows
from fkn_bench.metrics import MetricSettings, StatisticSums

__all__ = ["CellRecord", "Results"]


@dataclass(frozen=True, eq=False)
class CellRecord:
    """A cell's outcome as data: what :func:`fkn_bench.harness.cell.run_cell` returns.

    Attributes:
        key: :meth:`fkn_bench.harness.grid.CellSpec.key` (resume compares it).
        source: the source's ``describe()``.
        status: ``"ok"`` or ``"failed"``.
        rows: tidy rows (:mod:`fkn_bench.harness.rows`), cost rows included.
        nees, nis: per-step sums over the cell's runs for the Monte Carlo averages (None when
            the estimator reports no covariances / innovations, or failed).
        error: the exception (type and message) of a failed cell.
        notes: extra facts (the traceback of a failure, an online run that failed while the batch
            succeeded).
        provenance: :func:`fkn_bench.provenance.environment` of the process that ran it.
    """

    estimator: str
    scenario: str
    seeds: tuple[int, ...]
    key: dict[str, Any]
    source: dict[str, Any]
    status: str
    rows: pd.DataFrame
    nees: StatisticSums | None = None
    nis: StatisticSums | None = None
    error: str | None = None
    notes: dict[str, Any] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)

    @property
    def label(self) -> str:
        """The estimator with the options it ran with (module docstring)."""
        return estimator_label(self.estimator, self.key.get("estimator_options") or ())

    @property
    def training_seed(self) -> int | None:
        """The training seed of a training-seed replica (a cell run with the option
        ``training_seed=K`` alone, :data:`fkn_bench.harness.estimators.TRAINING_SEED_OPTION`),
        else None."""
        options = self.key.get("estimator_options") or ()
        if len(options) == 1 and options[0][0] == "training_seed":
            return int(options[0][1])
        return None

    @property
    def name(self) -> str:
        """Human-readable cell name, e.g. ``manual-ekf/ds1/seeds-0-9``
        (:attr:`fkn_bench.harness.grid.CellSpec.name`)."""
        return f"{self.label}/{self.scenario}/seeds-{self.seeds[0]}-{self.seeds[-1]}"

    @property
    def settings(self) -> MetricSettings:
        return MetricSettings.from_dict(self.key["settings"])


def _pool(parts: Sequence[StatisticSums | None]) -> StatisticSums | None:
    present = [p for p in parts if p is not None]
    return functools.reduce(operator.add, present) if present else None


def _differences(a: Any, b: Any) -> tuple[str, str]:
    """Two differing key parts in a message: source keys as they are; settings by the fields
    that differ (``cut=300`` and ``cut=100``)."""
    if isinstance(a, dict) and isinstance(b, dict):
        fields = [k for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]
        return tuple(", ".join(f"{k}={json.dumps(d.get(k))}" for k in fields) for d in (a, b))  # type: ignore[return-value]
    return str(a), str(b)


class Results:
    """Records of many cells (any order in, canonical order inside: pooled sums are identical
    whatever order cells finished in). "Estimator" in the methods below means the label
    (module docstring)."""

    def __init__(self, records: Iterable[CellRecord]) -> None:
        self.records: list[CellRecord] = sorted(records, key=lambda r: (r.label, r.scenario, r.seeds))
        self._by_pair: dict[tuple[str, str], list[CellRecord]] = {}  # (label, scenario) -> records, in order
        for record in self.records:
            self._by_pair.setdefault((record.label, record.scenario), []).append(record)
        self.bounds: dict[str, dict[str, Any]] = {}
        """``{scenario: bound}``: the stored posterior Cramér-Rao bounds that belong to these
        records (:mod:`fkn_bench.harness.bounds`; :meth:`ResultStore.load` reads them)."""

    def __len__(self) -> int:
        return len(self.records)

    @property
    def rows(self) -> pd.DataFrame:
        """All tidy rows, sorted (:func:`fkn_bench.harness.rows.sort_rows`)."""
        if not self.records:
            return pd.DataFrame(columns=list(COLUMNS))
        return sort_rows(pd.concat([r.rows for r in self.records], ignore_index=True))

    def pairs(self) -> list[tuple[str, str]]:
        """Distinct ``(estimator label, scenario)`` pairs, sorted."""
        return sorted({(r.label, r.scenario) for r in self.records})

    def estimators(self) -> list[str]:
        """Distinct estimator labels, sorted."""
        return sorted({r.label for r in self.records})

    def scenarios(self) -> list[str]:
        return sorted({r.scenario for r in self.records})

    def cells(self, estimator: str, scenario: str) -> list[CellRecord]:
        """The records of one pair (``estimator``: a label), in seed order."""
        return list(self._by_pair.get((estimator, scenario), ()))

    def seeds(self, estimator: str, scenario: str) -> list[int]:
        return [s for r in self.cells(estimator, scenario) for s in r.seeds]

    def pooled(self, estimator: str, scenario: str) -> tuple[StatisticSums | None, StatisticSums | None]:
        """Per-step NEES and NIS sums over every run of the pair (failed cells contribute none)."""
        cells = self.cells(estimator, scenario)
        return _pool([c.nees for c in cells]), _pool([c.nis for c in cells])

    def settings(self, scenario: str | None = None) -> MetricSettings:
        """The metric settings shared by the records (of ``scenario``); raises ``ValueError`` when
        records disagree (their numbers would not be comparable)."""
        records = [r for r in self.records if scenario is None or r.scenario == scenario]
        if not records:
            return MetricSettings()
        first = records[0].key["settings"]
        for record in records[1:]:
            if record.key["settings"] != first:
                raise ValueError(
                    f"results mix metric settings ({record.estimator}/{record.scenario} differs from "
                    f"{records[0].estimator}/{records[0].scenario}); rerun them with the same settings"
                )
        return MetricSettings.from_dict(first)

    def check_comparable(self) -> None:
        """Raise ``ValueError`` (one line) when the records of one scenario were scored on
        different data or with different metric settings (a split, a ``cut``, a scenario
        configuration of their own): their numbers cannot share a ranking."""
        first: dict[str, CellRecord] = {}
        for record in self.records:
            seen = first.setdefault(record.scenario, record)
            for part, what in (("source", "data (split or scenario configuration)"), ("settings", "metric settings")):
                if record.key.get(part) != seen.key.get(part):
                    mine, theirs = _differences(record.key.get(part), seen.key.get(part))
                    raise ValueError(
                        f"results mix {what} for scenario {record.scenario}: {mine} (cell {record.name}) and {theirs} "
                        f"(cell {seen.name}); keep one split, cut and scenario configuration per results directory "
                        f"(fkn-bench run --out another directory)"
                    )

    def source(self, scenario: str) -> dict[str, Any]:
        """The source description of ``scenario``'s records (the first one's)."""
        for record in self.records:
            if record.scenario == scenario:
                return record.source
        raise KeyError(scenario)
