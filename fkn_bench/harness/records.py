"""Cell records (a cell's outcome in plain data: no estimator, no source object) and their
collection (:class:`Results`): what the store reads and writes and what summaries, leaderboards
and plots consume."""

from __future__ import annotations

import functools
import operator
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import pandas as pd

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
    def name(self) -> str:
        """Human-readable cell name, e.g. ``manual-ekf/ds1/seeds-0-9``."""
        return f"{self.estimator}/{self.scenario}/seeds-{self.seeds[0]}-{self.seeds[-1]}"

    @property
    def settings(self) -> MetricSettings:
        return MetricSettings.from_dict(self.key["settings"])


def _pool(parts: Sequence[StatisticSums | None]) -> StatisticSums | None:
    present = [p for p in parts if p is not None]
    return functools.reduce(operator.add, present) if present else None


class Results:
    """Records of many cells (any order in, canonical order inside: pooled sums are identical
    whatever order cells finished in)."""

    def __init__(self, records: Iterable[CellRecord]) -> None:
        self.records: list[CellRecord] = sorted(records, key=lambda r: (r.estimator, r.scenario, r.seeds))

    def __len__(self) -> int:
        return len(self.records)

    @property
    def rows(self) -> pd.DataFrame:
        """All tidy rows, sorted (:func:`fkn_bench.harness.rows.sort_rows`)."""
        if not self.records:
            return pd.DataFrame(columns=list(COLUMNS))
        return sort_rows(pd.concat([r.rows for r in self.records], ignore_index=True))

    def pairs(self) -> list[tuple[str, str]]:
        """Distinct ``(estimator, scenario)`` pairs, sorted."""
        return sorted({(r.estimator, r.scenario) for r in self.records})

    def estimators(self) -> list[str]:
        return sorted({r.estimator for r in self.records})

    def scenarios(self) -> list[str]:
        return sorted({r.scenario for r in self.records})

    def cells(self, estimator: str, scenario: str) -> list[CellRecord]:
        """The records of one pair, in seed order."""
        return [r for r in self.records if r.estimator == estimator and r.scenario == scenario]

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

    def source(self, scenario: str) -> dict[str, Any]:
        """The source description of ``scenario``'s records (the first one's)."""
        for record in self.records:
            if record.scenario == scenario:
                return record.source
        raise KeyError(scenario)
