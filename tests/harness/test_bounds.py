"""Stored bounds (:mod:`fkn_bench.harness.bounds`): keyed by the results they belong to (source,
cut, seeds); a stale or corrupt file is never read, and :func:`store_bounds` replaces it."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from fkn_bench.harness import ResultStore
from fkn_bench.harness.bounds import bound_key, bound_path, read_bounds, store_bounds
from fkn_bench.harness.records import Results
from fkn_bench.io import read_json, write_json_atomic


@pytest.fixture
def ds1_results(small_results_dir: Path, tmp_path: Path) -> tuple[Path, Results]:
    """A copy of the small stored grid (the shared one stays untouched), its short ds1 only."""
    root = tmp_path / "results"
    shutil.copytree(small_results_dir, root)
    results = ResultStore(root).load()
    return root, Results([r for r in results.records if r.scenario == "ds1"])


def test_stored_bound_is_read_back_and_attached(ds1_results: tuple[Path, Results]) -> None:
    root, results = ds1_results
    assert store_bounds(root, results, progress=lambda s: None) == ["ds1"]
    stored = read_bounds(root, results)
    assert list(stored) == ["ds1"] and stored["ds1"]["seeds"] == list(range(12))
    assert stored["ds1"]["cut"] == results.settings("ds1").cut
    assert ResultStore(root).load().bounds["ds1"] == stored["ds1"]
    assert store_bounds(root, results) == []  # up to date: not recomputed


def test_stale_key_is_not_read(ds1_results: tuple[Path, Results]) -> None:
    root, results = ds1_results
    store_bounds(root, results)
    fewer = Results([r for r in results.records if max(r.seeds) < 10])  # other seeds: another key
    assert bound_key(fewer, "ds1")["seeds"] != bound_key(results, "ds1")["seeds"]
    assert read_bounds(root, fewer) == {}
    document = read_json(bound_path(root, "ds1"))
    document["key"]["cut"] += 1  # computed for another cut
    write_json_atomic(bound_path(root, "ds1"), document)
    assert read_bounds(root, results) == {}
    assert store_bounds(root, results) == ["ds1"]  # recomputed
    assert read_json(bound_path(root, "ds1"))["key"] == bound_key(results, "ds1")


def test_corrupt_bound_is_ignored_and_recomputed(ds1_results: tuple[Path, Results]) -> None:
    root, results = ds1_results
    path = bound_path(root, "ds1")
    path.parent.mkdir(parents=True)
    path.write_text('{"key": ', encoding="utf-8")
    assert read_bounds(root, results) == {}
    assert ResultStore(root).load().bounds == {}
    assert store_bounds(root, results) == ["ds1"]
    assert list(read_bounds(root, results)) == ["ds1"]
    write_json_atomic(path, {"key": bound_key(results, "ds1")})  # the right key, no bound
    assert read_bounds(root, results) == {}
