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
from fkn_bench.harness.sources import SimulatedSource
from fkn_bench.harness.store import MARKER, read_rows_csv, rows_to_csv
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
    assert json_path == tmp_path / "cells" / "manual-ekf" / "ds1" / "seeds-3-4.json"
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
    with pytest.raises(StoreError, match=rf"cannot write to {file}/sub: Not a directory"):
        ResultStore(file / "sub").prepare()
    assert file.read_text() == "mine\n"
