"""Grid runs: resume without recomputing, interrupted grids, failures kept as results, edited
cells recomputed, and only into a results directory of fkn-bench's."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path

import pandas as pd
import pytest

from fkn_bench.harness import (
    CellRecord,
    CellSpec,
    ForeignDirectoryError,
    LocalBackend,
    ResultStore,
    build_grid,
    deterministic_rows,
    run_grid,
)
from fkn_bench.harness.sources import SimulatedSource
from fkn_bench.harness.store import read_rows_csv


class CountingBackend(LocalBackend):
    """The local backend, counting cells and optionally interrupted after ``stop_after`` cells."""

    def __init__(self, stop_after: int | None = None) -> None:
        super().__init__(1)
        self.ran: list[str] = []
        self.stop_after = stop_after

    def run(self, cells: Sequence[CellSpec]) -> Iterator[CellRecord]:
        for result in super().run(cells):
            if self.stop_after is not None and len(self.ran) >= self.stop_after:
                raise KeyboardInterrupt
            self.ran.append(result.name)
            yield result


def test_resume_skips_finished_cells(tmp_path: Path, short_ds1: SimulatedSource) -> None:
    cells = build_grid(["manual-ekf"], [short_ds1], range(15))
    store = ResultStore(tmp_path)
    first = run_grid(cells, store=store, backend=CountingBackend(), progress=False)
    assert (first.computed, first.reused, first.failed) == (2, 0, 0)
    backend = CountingBackend()
    again = run_grid(cells, store=store, backend=backend, progress=False)
    assert (again.computed, again.reused) == (0, 2) and backend.ran == []
    pd.testing.assert_frame_equal(again.results.rows, first.results.rows, check_exact=True)
    assert (tmp_path / "results.csv").exists() and (tmp_path / "results.json").exists()
    rerun = run_grid(cells, store=store, backend=CountingBackend(), progress=False, rerun=True)
    assert rerun.computed == 2


def test_interrupted_grid_resumes_where_it_stopped(tmp_path: Path, short_ds1: SimulatedSource,
                                                    short_ds2: SimulatedSource) -> None:
    cells = build_grid(["manual-ekf"], [short_ds1, short_ds2], range(12))  # 4 cells
    store = ResultStore(tmp_path)
    with pytest.raises(KeyboardInterrupt):
        run_grid(cells, store=store, backend=CountingBackend(stop_after=2), progress=False)
    assert len(store.cell_files()) == 2
    assert not list(tmp_path.rglob("*.tmp"))  # nothing torn left behind
    backend = CountingBackend()
    resumed = run_grid(cells, store=store, backend=backend, progress=False)
    assert (resumed.computed, resumed.reused) == (2, 2)
    assert backend.ran == [c.name for c in cells[2:]]
    fresh = run_grid(cells, progress=False)
    pd.testing.assert_frame_equal(deterministic_rows(resumed.results.rows), deterministic_rows(fresh.results.rows),
                                  check_exact=True)


def test_failures_are_results(tmp_path: Path, short_ds1: SimulatedSource, test_estimators: None) -> None:
    cells = build_grid(["raising", "manual-ekf"], [short_ds1], range(3))
    outcome = run_grid(cells, store=ResultStore(tmp_path), progress=False)
    assert outcome.failed == 1 and outcome.computed == 2
    loaded = ResultStore(tmp_path).load()
    statuses = {r.estimator: r.status for r in loaded.records}
    assert statuses == {"raising": "failed", "manual-ekf": "ok"}
    again = run_grid(cells, store=ResultStore(tmp_path), progress=False)
    assert again.reused == 2  # a failure is a finished result


def test_without_store_results_stay_in_memory(short_ds1: SimulatedSource) -> None:
    outcome = run_grid(build_grid(["manual-ekf"], [short_ds1], range(2)), progress=False)
    assert len(outcome.results) == 1 and outcome.results.seeds("manual-ekf", "ds1") == [0, 1]


def test_resume_recomputes_an_edited_cell_and_says_so(tmp_path: Path, short_ds1: SimulatedSource,
                                                      capsys: pytest.CaptureFixture) -> None:
    cells = build_grid(["manual-ekf"], [short_ds1], range(15))  # 2 cells
    store = ResultStore(tmp_path)
    first = run_grid(cells, store=store, progress=False)
    (csv_path,) = (tmp_path / "cells" / "manual-ekf" / "ds1").glob("*/seeds-10-14.csv")
    text, original = csv_path.read_text(), read_rows_csv(csv_path)
    start = text.index(",state,rmse,") + len(",state,rmse,")
    csv_path.write_text(text[:start] + "16.67" + text[text.index(",", start):])
    capsys.readouterr()
    backend = CountingBackend()
    again = run_grid(cells, store=store, backend=backend, progress=False)
    assert backend.ran == ["manual-ekf/ds1/seeds-10-14"] and (again.computed, again.reused) == (1, 1)
    assert again.mismatched == ("manual-ekf/ds1/seeds-10-14",)
    err = capsys.readouterr().err
    assert "seeds-10-14.csv does not match the SHA-256 its record holds (edited or corrupted); recomputing it" in err
    pd.testing.assert_frame_equal(deterministic_rows(again.results.rows), deterministic_rows(first.results.rows),
                                  check_exact=True)
    recomputed = deterministic_rows(read_rows_csv(csv_path)).reset_index(drop=True)  # replaced the edited file
    pd.testing.assert_frame_equal(recomputed, deterministic_rows(original).reset_index(drop=True), check_exact=True)


def test_a_foreign_directory_is_refused_before_anything_runs(tmp_path: Path, short_ds1: SimulatedSource) -> None:
    (tmp_path / "results.csv").write_text("mine\n")
    backend = CountingBackend()
    with pytest.raises(ForeignDirectoryError, match="not an fkn-bench results directory"):
        run_grid(build_grid(["manual-ekf"], [short_ds1], range(2)), store=ResultStore(tmp_path), backend=backend, progress=False)
    assert backend.ran == [] and (tmp_path / "results.csv").read_text() == "mine\n"


def test_a_run_that_computes_nothing_leaves_the_summary_files_untouched(tmp_path: Path, short_ds1: SimulatedSource,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 20, item 6: regenerating committed results with every cell reused must leave the
    tree clean, even on another machine or commit (the provenance is the computing run's)."""
    import fkn_bench.harness.runner as runner

    store = ResultStore(tmp_path / "out")
    cells = build_grid(["manual-ekf"], [short_ds1], [0, 1], chunk_size=1)
    run_grid(cells, store=store, progress=False)
    before = {name: (tmp_path / "out" / name).read_bytes() for name in ("results.csv", "results.json")}
    monkeypatch.setattr(runner, "environment", lambda: {"commit": "another", "platform": "elsewhere"})
    again = run_grid(cells, store=store, progress=False)
    assert again.computed == 0
    assert {name: (tmp_path / "out" / name).read_bytes() for name in before} == before
    run_grid(cells[:1], store=store, progress=False)  # another grid (one cell): a new summary
    assert b"elsewhere" in (tmp_path / "out" / "results.json").read_bytes()


def _stored(root: Path) -> dict[str, object]:
    """What a run leaves in ``root``, timings aside: the file names, results.csv's and each cell's
    deterministic rows, each cell's sums and its record (key, status, checksummed files)."""
    import json

    import numpy as np

    names = sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file())
    stored: dict[str, object] = {"files": names}
    for name in names:
        path = root / name
        if name.endswith(".csv"):
            stored[name] = deterministic_rows(read_rows_csv(path)).to_csv()
        elif name.endswith(".npz"):
            with np.load(path) as npz:
                stored[name] = {k: npz[k].tolist() for k in npz.files}
        elif name.startswith("cells/"):
            document = json.loads(path.read_text())
            stored[name] = {k: document[k] for k in ("key", "status", "seeds", "files")}
    return stored


def test_a_run_killed_at_any_write_resumes_to_what_an_uninterrupted_run_gives(
        tmp_path: Path, short_ds1: SimulatedSource, kill_at_write) -> None:  # noqa: ANN001
    """Issue 34, finding 6: the marker (write 1), each cell's CSV, NPZ and JSON (2-7), results.csv
    and results.json (8, 9); a killed write leaves a stray temporary file, which the resumed run
    removes."""
    from fkn_bench.metrics import MetricSettings

    cells = build_grid(["manual-ekf"], [short_ds1], [0, 1], chunk_size=1, settings=MetricSettings(cut=150), online_steps=5)
    run_grid(cells, store=ResultStore(tmp_path / "whole"), progress=False)
    expected = _stored(tmp_path / "whole")
    for n in (1, 3, 4, 8, 9):
        out = tmp_path / f"killed-{n}"
        with kill_at_write(n) as written:
            run_grid(cells, store=ResultStore(out), progress=False)
        assert len(written) == n - 1 and list(out.rglob("*.tmp")), n  # killed there, a temporary left behind
        run_grid(cells, store=ResultStore(out), progress=False)
        assert _stored(out) == expected, n


def test_a_second_run_into_the_same_directory_is_refused(tmp_path: Path, short_ds1: SimulatedSource) -> None:
    from fkn_bench.io import LockedError, directory_lock

    backend = CountingBackend()
    with directory_lock(tmp_path, "results"):
        with pytest.raises(LockedError, match="in use by another fkn-bench process"):
            run_grid(build_grid(["manual-ekf"], [short_ds1], [0]), store=ResultStore(tmp_path), backend=backend,
                     progress=False)
    assert backend.ran == [] and not (tmp_path / "cells").exists()
