"""Running a grid: skip finished cells, run the rest on a backend, write each as it completes.

:func:`run_grid` is what ``fkn-bench run`` calls. With a :class:`~fkn_bench.harness.store.ResultStore`
every cell is written atomically the moment it completes, so an interrupted grid resumes where it
stopped (finished cells are read back, not recomputed; a finished cell whose data no longer
matches its recorded checksums is recomputed, with a line on stderr); without one, results stay
in memory. The store must be fkn-bench's (:meth:`~fkn_bench.harness.store.ResultStore.prepare`,
checked before anything runs), and the run holds its lock throughout
(:meth:`~fkn_bench.harness.store.ResultStore.session`: a second run into the same directory is
refused with :class:`fkn_bench.io.LockedError`). A failed write (a full disk:
:class:`fkn_bench.io.DiskFullError`) stops the run with that error; the cells finished before it
are kept and the one being written is not finished, so rerunning resumes.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from contextlib import nullcontext
from dataclasses import dataclass
from typing import Any

from tqdm import tqdm

from fkn_bench.harness.backends import Backend, LocalBackend
from fkn_bench.harness.grid import CellSpec
from fkn_bench.provenance import environment
from fkn_bench.harness.records import CellRecord, Results
from fkn_bench.harness.store import CellChecksumError, ResultStore

__all__ = ["GridRun", "run_grid", "grid_provenance"]


@dataclass(frozen=True, eq=False)
class GridRun:
    """Outcome of :func:`run_grid`: the results of every requested cell, and how many cells were
    ``computed`` now, ``reused`` from the store, and ``failed`` (among both); ``mismatched``
    names the stored cells recomputed because their data did not match their checksums."""

    results: Results
    computed: int
    reused: int
    failed: int
    mismatched: tuple[str, ...] = ()


def grid_provenance(cells: Sequence[CellSpec], backend: Backend) -> dict[str, Any]:
    """JSON provenance of a grid run: environment, backend, sources, seeds, settings."""
    sources: dict[str, Any] = {}
    for cell in cells:
        sources.setdefault(cell.scenario, cell.source.describe())
    return {
        "format": "fkn-bench-results",
        "environment": environment(),
        "backend": {"name": backend.name, "workers": getattr(backend, "workers", 1),
                    "scheduler": getattr(backend, "scheduler", None)},
        "estimators": list(dict.fromkeys(c.label for c in cells)),
        "sources": sources,
        "seeds": sorted({s for c in cells for s in c.seeds}),
        "settings": cells[0].settings.to_dict() if cells else None,
        "cells": len(cells),
    }


def run_grid(
    cells: Sequence[CellSpec],
    *,
    store: ResultStore | None = None,
    backend: Backend | None = None,
    progress: bool = True,
    rerun: bool = False,
    force: bool = False,
) -> GridRun:
    """Run ``cells`` (module docstring). ``rerun`` recomputes finished cells too; ``progress``
    shows a tqdm bar on stderr; ``force`` writes into a ``store`` that fkn-bench did not create.
    Raises :class:`~fkn_bench.harness.store.StoreError` before running anything when ``store``
    is not fkn-bench's, :class:`fkn_bench.io.WriteError` when it cannot be written and
    :class:`fkn_bench.io.LockedError` when another process is writing there."""
    backend = backend or LocalBackend()
    with store.session(force=force) if store is not None else nullcontext():
        return _run(cells, store, backend, progress, rerun)


def _run(cells: Sequence[CellSpec], store: ResultStore | None, backend: Backend, progress: bool, rerun: bool) -> GridRun:
    records: list[CellRecord] = []
    todo: list[CellSpec] = []
    mismatched: list[str] = []
    for cell in cells:
        try:
            done = None if (store is None or rerun) else store.finished(cell)
        except CellChecksumError as exc:
            print(f"fkn-bench run: {exc}; recomputing it", file=sys.stderr)
            mismatched.append(cell.name)
            done = None
        if done is None:
            todo.append(cell)
        else:
            records.append(done)
    reused = len(records)
    with tqdm(total=len(cells), initial=reused, desc="fkn-bench run", unit="cell", file=sys.stderr,
              disable=not progress, dynamic_ncols=True) as bar:
        for record in backend.run(todo) if todo else ():
            if store is not None:
                store.write_cell(record)
            records.append(record)
            bar.set_postfix_str(record.name, refresh=False)
            bar.update(1)
    results = Results(records)
    if store is not None:
        store.write_summary(results, grid_provenance(cells, backend), computed=len(records) - reused)
    failed = sum(r.status != "ok" for r in records)
    return GridRun(results=results, computed=len(records) - reused, reused=reused, failed=failed, mismatched=tuple(mismatched))
