"""Result files: exact round trips, resume keys, loading, nothing torn or left behind, checksums
of each cell's data, and a root that must be fkn-bench's."""

from __future__ import annotations

from pathlib import Path

import hashlib
import json

import numpy as np
import pandas as pd
import pytest

from dataclasses import replace

from fkn_bench.harness import (
    CellChecksumError,
    CellSpec,
    ForeignDirectoryError,
    ResultStore,
    StoreError,
    resolve_estimator,
    run_cell,
)
from fkn_bench.harness.grid import variant_id
from fkn_bench.harness.sources import SimulatedSource
from fkn_bench.harness.store import MARKER, read_rows_csv, rows_to_csv
from fkn_bench.io import WriteError
from fkn_bench.metrics import MetricSettings


def _spec(source: SimulatedSource, fingerprint: str = "abc", **changes) -> CellSpec:
    resolved = replace(resolve_estimator("manual-ekf", source.scenario), fingerprint=fingerprint)
    fields = {"resolved": resolved, "source": source, "seeds": (3, 4), "settings": MetricSettings(), "online_steps": 20}
    fields.update(changes)
    return CellSpec(**fields)


def test_round_trip_is_exact(tmp_path: Path, short_ds1: SimulatedSource) -> None:
    record = run_cell(_spec(short_ds1))
    store = ResultStore(tmp_path)
    json_path = store.write_cell(record)
    assert json_path == tmp_path / "cells" / "manual-ekf" / "ds1" / variant_id(record.key) / "seeds-3-4.json"
    back = store.read_cell(json_path)
    pd.testing.assert_frame_equal(back.rows, record.rows, check_exact=True)
    # exact: a lossless write/read round trip of the cell (float64 values, integer counts)
    assert np.array_equal(back.nees.sum, record.nees.sum) and np.array_equal(back.nis.count, record.nis.count)
    assert back.key == record.key and back.status == "ok" and back.seeds == (3, 4)
    assert sorted(p.name for p in json_path.parent.iterdir()) == ["seeds-3-4.csv", "seeds-3-4.json", "seeds-3-4.npz"]


def test_finished_matches_the_key(tmp_path: Path, short_ds1: SimulatedSource) -> None:
    store = ResultStore(tmp_path)
    spec = _spec(short_ds1)
    assert store.finished(spec) is None
    store.write_cell(run_cell(spec))
    assert store.finished(spec) is not None
    assert store.finished(_spec(short_ds1, fingerprint="retuned")) is None
    assert store.finished(_spec(short_ds1, settings=MetricSettings(cut=50))) is None
    other_config = SimulatedSource(short_ds1.scenario.replace(noise_scale=2.0))
    assert store.finished(_spec(other_config)) is None


def test_torn_cell_is_not_finished(tmp_path: Path, short_ds1: SimulatedSource) -> None:
    store = ResultStore(tmp_path)
    spec = _spec(short_ds1)
    json_path = store.write_cell(run_cell(spec))
    json_path.with_suffix(".csv").unlink()
    assert store.finished(spec) is None
    with pytest.raises(StoreError, match="incomplete"):
        store.read_cell(json_path)


def test_load_errors(tmp_path: Path) -> None:
    with pytest.raises(StoreError, match="not found"):
        ResultStore(tmp_path / "missing").load()
    with pytest.raises(StoreError, match="no cell results"):
        ResultStore(tmp_path).load()


def test_csv_keeps_odd_names_and_nan(tmp_path: Path) -> None:
    rows = pd.DataFrame({"estimator": ["NA"], "scenario": ["nan"], "seed": [1], "group": ["g"], "metric": ["m"],
                         "value": [np.nan], "unit": [""]})
    path = tmp_path / "rows.csv"
    path.write_text(rows_to_csv(rows))
    back = read_rows_csv(path)
    assert back.estimator[0] == "NA" and back.scenario[0] == "nan" and np.isnan(back.value[0])
    assert back.unit[0] == ""


# ---------------------------------------------------------------------------- checksums
def test_cell_record_holds_the_sha256_of_its_data(tmp_path: Path, short_ds1: SimulatedSource) -> None:
    json_path = ResultStore(tmp_path).write_cell(run_cell(_spec(short_ds1)))
    document = json.loads(json_path.read_text())
    for kind, suffix in (("rows", ".csv"), ("sums", ".npz")):
        assert document["sha256"][kind] == hashlib.sha256(json_path.with_suffix(suffix).read_bytes()).hexdigest()


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_an_edited_cell_fails_its_checksum(tmp_path: Path, short_ds1: SimulatedSource, suffix: str) -> None:
    store = ResultStore(tmp_path)
    spec = _spec(short_ds1)
    json_path = store.write_cell(run_cell(spec))
    data = json_path.with_suffix(suffix)
    if suffix == ".csv":  # a hand edit that still parses: an RMSE of 16.67
        text = data.read_text()
        start = text.index(",state,rmse,") + len(",state,rmse,")
        data.write_text(text[:start] + "16.67" + text[text.index(",", start):])
        assert 16.67 in read_rows_csv(data)["value"].tolist()
    else:
        blob = bytearray(data.read_bytes())
        blob[-30] ^= 0xFF
        data.write_bytes(bytes(blob))
    message = rf"cell .*seeds-3-4\.json: seeds-3-4\{suffix} does not match the SHA-256 its record holds"
    with pytest.raises(CellChecksumError, match=message):
        store.finished(spec)
    with pytest.raises(CellChecksumError, match=message):
        store.load()


def test_a_cell_written_before_the_checksums_is_read_unchecked(tmp_path: Path, short_ds1: SimulatedSource) -> None:
    store = ResultStore(tmp_path)
    spec = _spec(short_ds1)
    record = run_cell(spec)
    json_path = store.write_cell(record)
    document = json.loads(json_path.read_text())
    del document["sha256"]  # the layout of the committed leaderboards/results
    json_path.write_text(json.dumps(document))
    legacy = store.finished(spec)
    assert legacy is not None
    pd.testing.assert_frame_equal(legacy.rows, record.rows, check_exact=True)


# ---------------------------------------------------------------------------- prepare (ownership)
def test_prepare_marks_a_new_or_empty_directory(tmp_path: Path) -> None:
    ResultStore(tmp_path / "new" / "results").prepare()
    assert (tmp_path / "new" / "results" / MARKER).is_file()
    (tmp_path / "empty").mkdir()
    ResultStore(tmp_path / "empty").prepare()
    assert (tmp_path / "empty" / MARKER).is_file()
    ResultStore(tmp_path / "empty").prepare()  # marked: ours from now on


def test_prepare_refuses_a_directory_fkn_bench_did_not_write(tmp_path: Path) -> None:
    for name in ("results.csv", "b.txt", "c.txt", "d.txt"):
        (tmp_path / name).write_text("mine\n")
    (tmp_path / "sub").mkdir()
    with pytest.raises(ForeignDirectoryError, match=rf"{tmp_path} is not an fkn-bench results directory: it holds "
                                                    rf"b\.txt, c\.txt, d\.txt and 2 more and no \{MARKER} marker"):
        ResultStore(tmp_path).prepare()
    assert not (tmp_path / MARKER).exists() and (tmp_path / "results.csv").read_text() == "mine\n"
    ResultStore(tmp_path).prepare(force=True)
    assert (tmp_path / MARKER).is_file() and (tmp_path / "b.txt").read_text() == "mine\n"


def test_prepare_recognises_an_earlier_runs_results(tmp_path: Path) -> None:
    (tmp_path / "results.json").write_text(json.dumps({"format": "fkn-bench-results"}))  # as before the marker
    (tmp_path / "NOTES.md").write_text("notes\n")
    ResultStore(tmp_path).prepare()
    assert (tmp_path / MARKER).is_file()
    other = tmp_path / "other"
    other.mkdir()
    (other / "results.json").write_text(json.dumps({"format": "something-else"}))
    with pytest.raises(ForeignDirectoryError, match="holds results.json and no"):
        ResultStore(other).prepare()


def test_prepare_refuses_a_file_or_a_path_it_cannot_write(tmp_path: Path) -> None:
    file = tmp_path / "results.csv"
    file.write_text("mine\n")
    with pytest.raises(StoreError, match=rf"{file} is a file, not a directory"):
        ResultStore(file).prepare(force=True)
    with pytest.raises(WriteError, match=rf"cannot write {file}/sub/\{MARKER}: Not a directory"):
        ResultStore(file / "sub").prepare()
    assert file.read_text() == "mine\n"


# ---------------------------------------------------------------------------- cell identity (issue 34, finding 3)
@pytest.fixture(scope="module")
def one_cell(short_ds1: SimulatedSource):  # noqa: ANN201
    """One computed cell of manual-ekf on short ds1 (seeds 3, 4), shared by the tests below."""
    return run_cell(_spec(short_ds1))


def _variant_specs(source: SimulatedSource) -> dict[str, CellSpec]:
    """The same estimator, scenario and seeds, differing in what changes the numbers."""
    gated = replace(resolve_estimator("manual-ekf", source.scenario), fingerprint="abc", options=(("gate", 0.5),))
    return {
        "plain": _spec(source),
        "val": _spec(SimulatedSource(source.scenario, "val")),
        "cut": _spec(source, settings=MetricSettings(cut=30)),
        "option": _spec(source, resolved=gated),
        "config": _spec(SimulatedSource(source.scenario.replace(noise_scale=2.0))),
    }


def test_cells_differing_in_split_cut_options_or_configuration_keep_their_own_files(
        tmp_path: Path, short_ds1: SimulatedSource, one_cell) -> None:  # noqa: ANN001
    store = ResultStore(tmp_path)
    specs = _variant_specs(short_ds1)
    paths = {name: store.write_cell(replace(one_cell, key=spec.key())) for name, spec in specs.items()}
    assert len(set(paths.values())) == len(specs)  # one file each: nothing overwritten
    assert {p.parent.parent for p in paths.values()} == {tmp_path / "cells" / "manual-ekf" / "ds1"}
    for name, spec in specs.items():
        assert store.finished(spec).key == spec.key(), name
    assert len(store.load()) == len(specs)
    # a retrained estimator (another fingerprint) replaces its cell, as before
    retrained = _spec(short_ds1, fingerprint="retrained")
    assert store.write_cell(replace(one_cell, key=retrained.key())) == paths["plain"]
    assert store.finished(specs["plain"]) is None and store.finished(retrained) is not None


def test_names_that_looked_alike_or_escape_get_their_own_cells_inside_cells(tmp_path: Path, one_cell) -> None:  # noqa: ANN001
    store = ResultStore(tmp_path)
    names = ["my fast", "my_fast", "my/fast", "..", ".", "../../outside"]
    paths = [store.write_cell(replace(one_cell, scenario=name)) for name in names]
    assert len(set(paths)) == len(names)
    for path in paths:
        assert path.resolve().is_relative_to((tmp_path / "cells" / "manual-ekf").resolve())
    assert sorted(r.scenario for r in store.load().records) == sorted(names)
    assert not (tmp_path.parent / "outside").exists()


# ---------------------------------------------------------------------------- kills, locks, old layout (finding 6)
def test_a_directory_holding_only_a_killed_runs_temporaries_and_lock_is_empty(tmp_path: Path) -> None:
    (tmp_path / f"{MARKER}.x1y2.tmp").write_text('{"format": "fkn-')  # a kill while writing the first marker
    (tmp_path / ".fkn-bench.lock").write_text("")
    with ResultStore(tmp_path).session():
        assert (tmp_path / MARKER).is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == [".fkn-bench-results", ".fkn-bench.lock"]  # stray file removed


def test_a_second_writer_is_refused_by_the_lock(tmp_path: Path) -> None:
    from fkn_bench.io import LockedError

    with ResultStore(tmp_path).session():
        with pytest.raises(LockedError, match=rf"{tmp_path} is in use by another fkn-bench process"):
            with ResultStore(tmp_path).session():
                pass


def test_cells_of_the_earlier_layout_are_read_and_moved_unchanged(tmp_path: Path, short_ds1: SimulatedSource,
                                                                 one_cell) -> None:  # noqa: ANN001
    store = ResultStore(tmp_path)
    store.prepare()
    json_path = store.write_cell(one_cell)
    legacy = tmp_path / "cells" / "manual-ekf" / "ds1"
    contents = {}
    for path in sorted(json_path.parent.iterdir()):
        contents[path.name] = path.read_bytes()
        path.rename(legacy / path.name)
    json_path.parent.rmdir()
    assert store.cell_files() == [legacy / "seeds-3-4.json"] and len(store.load()) == 1  # read where it is
    with store.session():
        pass
    assert store.cell_files() == [json_path] and store.finished(_spec(short_ds1)) is not None
    assert {p.name: p.read_bytes() for p in json_path.parent.iterdir()} == contents
    for name, data in contents.items():  # the same cell in both layouts (an older fkn-bench wrote it again)
        (legacy / name).write_bytes(data)
    assert len(store.cell_files()) == 2 and len(store.load()) == 1  # counted once
    with store.session():
        pass
    assert store.cell_files() == [json_path] and not list(legacy.glob("seeds-*"))


def test_a_failed_rewrite_leaves_no_cell_that_resume_trusts(tmp_path: Path, short_ds1: SimulatedSource, one_cell,  # noqa: ANN001
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    import errno

    from fkn_bench import io as fio
    from fkn_bench.io import DiskFullError

    store = ResultStore(tmp_path)
    spec = _spec(short_ds1)
    json_path = store.write_cell(one_cell)
    real_replace = fio.os.replace

    def full(src: str, dst: str) -> None:
        if str(dst).endswith(".npz"):
            raise OSError(errno.ENOSPC, "No space left on device")
        real_replace(src, dst)

    monkeypatch.setattr(fio.os, "replace", full)
    with pytest.raises(DiskFullError, match=r"no space left on the device to write .*seeds-3-4\.npz"):
        store.write_cell(one_cell)  # the CSV is replaced, the sums are not
    assert not json_path.exists() and store.finished(spec) is None  # recomputed, not trusted
