"""The run table (``fkn-bench run``'s summary text) and the number formats of the tables."""

from __future__ import annotations

from pathlib import Path

import pytest

from fkn_bench.harness import ResultStore, summarize_results
from fkn_bench.reporting.report import format_number, summary_text, text_table


def test_summary_text_has_one_line_per_pair(small_results_dir: Path) -> None:
    summaries = summarize_results(ResultStore(small_results_dir).load())
    lines = summary_text(summaries).splitlines()
    assert lines[0].startswith("estimator / scenario") and lines[2].startswith("manual-ekf / ds1")
    assert sum(" / ds" in line for line in lines[2:6]) == 4


@pytest.mark.parametrize("width", [80, 120])
def test_summary_text_fits_a_terminal(small_results_dir: Path, width: int) -> None:
    """Issue 20, item 7: the table was ~150 columns wide; on a terminal it is stacked to fit, each
    part led by the estimator and scenario, and the legend wrapped; every value still appears."""
    summaries = summarize_results(ResultStore(small_results_dir).load())
    wide, narrow = summary_text(summaries), summary_text(summaries, width=width)
    assert max(map(len, wide.splitlines())) > 120
    assert max(map(len, narrow.splitlines())) <= width
    header = wide.splitlines()[0].split("  ")
    assert all(column.strip() in narrow for column in header if column.strip())
    assert narrow.count("manual-ekf / ds1") >= 2  # the row names lead every part


def test_format_number() -> None:
    assert format_number(0.0197812) == "0.01978"
    assert format_number(5.4034, 3) == "5.40"
    assert format_number(1234.5, 3) == "1234"
    assert format_number(2e-6, 3) == "2.00e-06"
    assert format_number(float("nan")) == "-" and format_number(None) == "-"
    assert format_number(0) == "0"


def test_text_table_alignment() -> None:
    table = text_table(["name", "x"], [["a", "1"], ["long", "22"]])
    assert table.splitlines() == ["name   x", "----  --", "a      1", "long  22"]
