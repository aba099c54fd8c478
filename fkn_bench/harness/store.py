"""The result store: one directory per grid, one set of files per cell, written atomically.

Layout under the store's root::

    cells/<estimator>/<scenario>/<variant>/seeds-<first>-<last>.csv    tidy rows (exact float repr)
    cells/<estimator>/<scenario>/<variant>/seeds-<first>-<last>.npz    per-step NEES/NIS sums
    cells/<estimator>/<scenario>/<variant>/seeds-<first>-<last>.json   key, status, error, provenance
    results.csv                                                        rows of the last grid run, sorted
    results.json                                                       provenance of the last grid run

    .fkn-bench-results                                                 marker: fkn-bench writes here
    .fkn-bench.lock                                                    held while a run writes here

``<estimator>`` and ``<scenario>`` are the names encoded by
:func:`~fkn_bench.harness.grid.path_name` (one component each, distinct names never share one,
nothing escapes ``cells/``); ``<variant>`` is :func:`~fkn_bench.harness.grid.variant_id`, 12 hex
digits over the source key (scenario configuration hash, split), the metric settings (``cut``)
and the estimator options, so that runs differing there keep their own cells, while a retrained
estimator replaces its cell. Cells of the earlier layout without ``<variant>`` are read, and moved
into the new one when a run writes to the directory (:meth:`ResultStore.migrate`).

Each file is written atomically (:mod:`fkn_bench.io`) and the cell's JSON last (a replaced cell's
JSON is removed first), so a cell is finished exactly when its JSON exists: a kill or a full disk
at any point leaves no cell that resume trusts with data it did not record. Resume: a cell whose
JSON records the same key (estimator and its configuration fingerprint, source and its
configuration hash, seeds, metric settings, estimator options, format version) is not computed
again; failed cells count as finished (their failure is the result; use ``rerun`` to try again).

Concurrency: :meth:`ResultStore.session` holds :func:`fkn_bench.io.directory_lock` on the root
while a run writes there (a second run into it is refused with :class:`fkn_bench.io.LockedError`)
and removes the temporary files that killed writers left behind.

Integrity: a cell's JSON records the SHA-256 of its CSV and NPZ files (``sha256``), and reading
the cell checks them: a cell whose data was edited or corrupted raises :class:`CellChecksumError`
(resume recomputes it and says so). Cells written before the checksums (no ``sha256``) are read
unchecked, so older result directories still resume.

Ownership: :meth:`ResultStore.prepare` runs before anything is written and makes sure that the
root is fkn-bench's: a new or empty directory gets the marker file; a directory with the marker,
or with the ``results.json`` of an earlier run (``format: fkn-bench-results``; written before the
marker existed), is ours; any other directory is refused (:class:`ForeignDirectoryError`) unless
``force`` is given, so that nobody's ``results.csv`` is overwritten by surprise. fkn-bench's lock
file and stray temporary files do not count (a directory holding only what a run killed while
writing the marker left behind is empty).
"""

from __future__ import annotations

import fnmatch
import hashlib
import io
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

import numpy as np
import pandas as pd

from fkn_bench.harness.grid import CellSpec, path_name, variant_id
from fkn_bench.harness.bounds import read_bounds
from fkn_bench.harness.records import CellRecord, Results
from fkn_bench.io import (TEMPORARY_PATTERN, WriteError, directory_lock, read_json, remove_temporaries, to_jsonable,
                          write_bytes_atomic, write_json_atomic, write_text_atomic)
from fkn_bench.metrics import StatisticSums

__all__ = [
    "CELL_FORMAT",
    "MARKER",
    "CellChecksumError",
    "ForeignDirectoryError",
    "LOCK_FILE",
    "ResultStore",
    "StoreError",
    "read_rows_csv",
    "rows_to_csv",
]

CELL_FORMAT = "fkn-bench-cell"
RESULTS_FORMAT = "fkn-bench-results"
MARKER = ".fkn-bench-results"
"""The file that marks a directory as fkn-bench's results directory (module docstring)."""
LOCK_FILE = ".fkn-bench.lock"
"""The file :func:`fkn_bench.io.directory_lock` locks."""

_DTYPES = {"estimator": str, "scenario": str, "seed": np.int64, "group": str, "metric": str, "value": np.float64, "unit": str}


class StoreError(ValueError):
    """A results directory that cannot be read (missing, corrupt or of another format) or written."""


class ForeignDirectoryError(StoreError):
    """A results directory that fkn-bench did not write (no marker, no earlier results)."""


class CellChecksumError(StoreError):
    """A cell whose CSV or NPZ file does not match the SHA-256 recorded in its JSON."""


def _ignorable(name: str) -> bool:
    """fkn-bench's lock file and the temporary files of killed atomic writes."""
    return name == LOCK_FILE or fnmatch.fnmatchcase(name, TEMPORARY_PATTERN)


class _Named:
    """The estimator, scenario, seeds and key of a cell document (for :meth:`ResultStore._paths`)."""

    def __init__(self, document: dict[str, Any]) -> None:
        self.estimator, self.scenario = str(document["estimator"]), str(document["scenario"])
        self.seeds, self.key = [int(s) for s in document["seeds"]], dict(document["key"])


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def rows_to_csv(rows: pd.DataFrame, *, float_format: str | None = None) -> str:
    """CSV text of tidy rows; without ``float_format`` floats are written exactly (shortest
    round-trip repr) and NaN as an empty field."""
    buffer = io.StringIO()
    rows.to_csv(buffer, index=False, float_format=float_format, lineterminator="\n")
    return buffer.getvalue()


def read_rows_csv(path: str | Path | IO[bytes]) -> pd.DataFrame:
    """Read tidy rows written by :func:`rows_to_csv` (exact floats; names are never NaN)."""
    options: dict[str, Any] = {}
    if int(pd.__version__.split(".")[0]) < 3:  # pandas 3 parses round-trip exactly by default
        options["float_precision"] = "round_trip"
    return pd.read_csv(path, dtype=_DTYPES, keep_default_na=False, na_values={"value": [""]}, **options)


class ResultStore:
    """Cell files under ``root`` (module docstring)."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)

    # ------------------------------------------------------------------ ownership
    def check(self, *, force: bool = False) -> None:
        """Refuse a root that is not fkn-bench's, writing nothing (:meth:`prepare`'s checks)."""
        root = self.root
        if root.exists() and not root.is_dir():
            raise StoreError(f"{root} is a file, not a directory")
        if root.is_dir() and not force and not self._is_ours():
            try:
                entries = sorted(p.name + ("/" if p.is_dir() else "") for p in root.iterdir() if not _ignorable(p.name))
            except OSError as exc:
                raise StoreError(f"cannot read directory {root}: {exc.strerror or exc}") from None
            if entries:
                shown = ", ".join(entries[:3]) + (f" and {len(entries) - 3} more" if len(entries) > 3 else "")
                raise ForeignDirectoryError(
                    f"{root} is not an fkn-bench results directory: it holds {shown} and no {MARKER} marker"
                )

    def prepare(self, *, force: bool = False) -> None:
        """Make the root a results directory of fkn-bench's before anything is written there.

        A missing or empty directory (fkn-bench's lock file and stray temporary files aside) is
        created and marked (:data:`MARKER`); one with the marker or with an earlier run's
        ``results.json`` is ours (and marked); any other directory is refused with
        :class:`ForeignDirectoryError` naming some of its entries, unless ``force`` (it is marked
        and written into; files other than ``cells/``, ``results.csv`` and ``results.json`` are
        never touched). A root that is a file raises :class:`StoreError`; one that cannot be
        created or written raises :class:`fkn_bench.io.WriteError` (``DiskFullError`` when the
        disk is full), one line naming the path.
        """
        self.check(force=force)
        root = self.root
        if (root / MARKER).is_file():  # marked already: only check that it can be written (a rerun leaves no change)
            if not os.access(root, os.W_OK):
                raise StoreError(f"cannot write to {root}: permission denied")
            return
        write_json_atomic(root / MARKER, {"format": RESULTS_FORMAT, "note": "fkn-bench run --out writes here"})

    @contextmanager
    def session(self, *, force: bool = False) -> Iterator[ResultStore]:
        """Hold the root for writing: :meth:`check`, take the directory's lock
        (:func:`fkn_bench.io.directory_lock`; another process holding it raises
        :class:`fkn_bench.io.LockedError` at once), :meth:`prepare`, remove stray temporary files
        and :meth:`migrate` cells of the earlier layout; the lock is held until the block ends."""
        self.check(force=force)  # before the lock file is created in somebody else's directory
        with directory_lock(self.root, "results (fkn-bench run --out)"):
            self.prepare(force=force)
            remove_temporaries(self.root)
            self.migrate()
            yield self

    def _is_ours(self) -> bool:
        """The root holds the marker, or an earlier run's ``results.json``."""
        if (self.root / MARKER).is_file():
            return True
        try:
            document = read_json(self.root / "results.json")
        except (OSError, ValueError):
            return False
        return isinstance(document, dict) and document.get("format") == RESULTS_FORMAT

    # ------------------------------------------------------------------ paths
    def _paths(self, cell: CellSpec | CellRecord) -> tuple[Path, Path, Path]:
        """The cell's CSV, NPZ and JSON files (module docstring)."""
        key = cell.key() if callable(cell.key) else cell.key
        stem = self.root / "cells" / path_name(cell.estimator) / path_name(cell.scenario) / variant_id(key)
        stem /= f"seeds-{cell.seeds[0]}-{cell.seeds[-1]}"
        return stem.with_suffix(".csv"), stem.with_suffix(".npz"), stem.with_suffix(".json")

    def migrate(self) -> list[Path]:
        """Move the cells of the earlier layout (``cells/<estimator>/<scenario>/seeds-*``) to
        their place in this one, unchanged; returns their new JSON paths. Each file is renamed
        (atomic), the JSON last, so an interrupted migration goes on where it stopped. A legacy
        cell whose place already holds a finished cell (written there since) is the same cell
        computed earlier: its files are removed. A legacy JSON that is not a readable cell is left
        where it is. Call while holding the lock; a failure raises :class:`fkn_bench.io.WriteError`."""
        moved = []
        for old_json in sorted((self.root / "cells").glob("*/*/seeds-*.json")):
            try:
                document = read_json(old_json)
                new_csv, new_npz, new_json = self._paths(_Named(document))
            except (OSError, ValueError, KeyError, TypeError, IndexError):
                continue
            superseded = new_json.is_file()
            for old, new in ((old_json.with_suffix(".csv"), new_csv), (old_json.with_suffix(".npz"), new_npz),
                             (old_json, new_json)):
                try:
                    if superseded:
                        old.unlink(missing_ok=True)
                    elif old.is_file():
                        new.parent.mkdir(parents=True, exist_ok=True)
                        os.replace(old, new)
                except OSError as exc:
                    raise WriteError(f"cannot move the cell file {old} to {new}: {exc.strerror or exc}", new) from None
            if not superseded:
                moved.append(new_json)
        return moved

    # ------------------------------------------------------------------ resume
    def finished(self, spec: CellSpec) -> CellRecord | None:
        """The stored record of ``spec`` when it is finished with the same key, else None.

        Raises :class:`CellChecksumError` when the cell's data does not match its checksums (the
        caller recomputes it and says so); a missing or torn cell is simply not finished."""
        try:
            record = self.read_cell(self._paths(spec)[2])
        except CellChecksumError:
            raise
        except StoreError:  # missing (read_json's FileNotFoundError) or broken
            return None
        return record if record.key == spec.key() else None

    # ------------------------------------------------------------------ write
    def write_cell(self, record: CellRecord) -> Path:
        """Write the record's rows, sums and JSON (last) atomically, after removing the JSON of
        the cell it replaces (module docstring); returns the JSON path."""
        csv_path, npz_path, json_path = self._paths(record)
        json_path.unlink(missing_ok=True)
        rows = rows_to_csv(record.rows).encode("utf-8")
        write_bytes_atomic(csv_path, rows)
        arrays: dict[str, np.ndarray] = {}
        for name, sums in (("nees", record.nees), ("nis", record.nis)):
            if sums is not None:
                arrays.update({f"{name}_sum": sums.sum, f"{name}_count": sums.count})
        buffer = io.BytesIO()
        np.savez_compressed(buffer, **arrays)
        write_bytes_atomic(npz_path, sums_data := buffer.getvalue())
        document = {
            "format": CELL_FORMAT,
            "cell": record.name,
            "estimator": record.estimator,
            "scenario": record.scenario,
            "seeds": list(record.seeds),
            "status": record.status,
            "error": record.error,
            "key": record.key,
            "source": record.source,
            "files": {"rows": csv_path.name, "sums": npz_path.name},
            "sha256": {"rows": _sha256(rows), "sums": _sha256(sums_data)},
            "notes": record.notes,
            "provenance": record.provenance,
        }
        return write_json_atomic(json_path, document)

    # ------------------------------------------------------------------ read
    def read_cell(self, json_path: str | Path) -> CellRecord:
        """Read one finished cell (raises :class:`StoreError`; :class:`CellChecksumError` when
        its data does not match the checksums its JSON records)."""
        json_path = Path(json_path)
        try:
            document = read_json(json_path)
        except (OSError, ValueError) as exc:
            raise StoreError(str(exc)) from None
        if not isinstance(document, dict) or document.get("format") != CELL_FORMAT:
            raise StoreError(f"{json_path} is not an fkn-bench cell file")
        try:
            data = {kind: json_path.with_name(document["files"][kind]).read_bytes() for kind in ("rows", "sums")}
        except (OSError, KeyError, TypeError) as exc:
            raise StoreError(f"cell {json_path} is incomplete: {exc}") from None
        checksums = document.get("sha256")  # absent in cells written before the checksums: unchecked
        if checksums is not None:
            for kind, content in data.items():
                recorded = checksums.get(kind) if isinstance(checksums, dict) else None
                if recorded != _sha256(content):
                    raise CellChecksumError(
                        f"cell {json_path}: {document['files'][kind]} does not match the SHA-256 its record holds "
                        f"(edited or corrupted)"
                    )
        try:
            rows = read_rows_csv(io.BytesIO(data["rows"]))
            with np.load(io.BytesIO(data["sums"]), allow_pickle=False) as npz:
                sums = {name: np.array(npz[name]) for name in npz.files}
        except (OSError, KeyError, ValueError) as exc:
            raise StoreError(f"cell {json_path} is incomplete: {exc}") from None

        pairs = {name: StatisticSums(sums[f"{name}_sum"], sums[f"{name}_count"])
                 for name in ("nees", "nis") if f"{name}_sum" in sums}
        return CellRecord(
            **{k: document[k] for k in ("estimator", "scenario", "key", "source", "status")},
            seeds=tuple(int(s) for s in document["seeds"]),
            rows=rows,
            **pairs,
            error=document.get("error"),
            notes=document.get("notes") or {},
            provenance=document.get("provenance") or {},
        )

    def cell_files(self) -> list[Path]:
        """JSON files of the stored cells (the earlier layout's too), sorted."""
        cells = self.root / "cells"
        return sorted([*cells.glob("*/*/*/seeds-*.json"), *cells.glob("*/*/seeds-*.json")])

    def load(self) -> Results:
        """Every stored cell (raises :class:`StoreError` when there are none or one is broken); a
        cell of the earlier layout that was also written in this one (not yet :meth:`migrate` d)
        counts once, as the newer layout's."""
        if not self.root.is_dir():
            raise StoreError(f"results directory not found: {self.root}")
        files = self.cell_files()
        if not files:
            raise StoreError(f"no cell results under {self.root} (expected cells/<estimator>/<scenario>/<variant>/"
                             f"seeds-*.json)")
        records: dict[Path, CellRecord] = {}
        for path in files:
            record = self.read_cell(path)
            place = self._paths(record)[2]
            if path == place or place not in records:
                records[place] = record
        results = Results(records.values())
        results.bounds = read_bounds(self.root, results)
        return results

    def write_summary(self, results: Results, provenance: dict[str, Any], *, computed: int | None = None) -> None:
        """Write ``results.csv`` (all rows, exact floats) and ``results.json`` (provenance).

        Files whose content would not change are not rewritten, and a run that ``computed`` no
        cell (every one reused) keeps the stored ``results.json`` when it describes the same grid
        (estimators, sources, seeds, settings): its provenance stays that of the run that computed
        the cells, and a no-op regeneration of committed results leaves the tree clean."""
        csv_path, json_path = self.root / "results.csv", self.root / "results.json"
        text = rows_to_csv(results.rows)
        if not (csv_path.is_file() and csv_path.read_text(encoding="utf-8") == text):
            write_text_atomic(csv_path, text)
        if computed == 0 and json_path.is_file():
            try:
                stored = read_json(json_path)
            except (OSError, ValueError):
                stored = None
            grid = lambda document: {k: v for k, v in document.items() if k not in ("environment", "backend")}  # noqa: E731
            if isinstance(stored, dict) and grid(stored) == grid(to_jsonable(provenance)):
                return
        write_json_atomic(json_path, provenance)
