"""Leaderboard building: ranking, quoted paper rows, determinism, formats."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pandas as pd
import pytest

from fkn_bench.harness import ResultStore, build_grid, run_grid
from fkn_bench.harness.sources import SimulatedSource
from fkn_bench.reporting.leaderboard import REGENERATE_COMMAND, build_leaderboards, covariance_verdict, rank, write_leaderboards
from fkn_bench.reporting.reference import PAPER_ROWS, quoted_rows
from fkn_bench.reporting.tables import Table, html_table, markdown_table


@pytest.fixture(scope="module")
def files(small_results_dir: Path) -> dict[str, str]:
    return build_leaderboards(ResultStore(small_results_dir).load())


def test_file_set(files: dict[str, str]) -> None:
    assert set(files) == {"README.md", "results.csv", "provenance.json"} | {
        f"{s}.{ext}" for s in ("ds1", "ds2") for ext in ("md", "html", "csv")
    }


def test_ranking_by_primary_score(files: dict[str, str]) -> None:
    ranking = pd.read_csv(io.StringIO(files["ds1.csv"]))
    assert list(ranking.estimator) == ["oracle-ekf", "manual-ekf"]  # the oracle is more accurate on ds1
    assert list(ranking["rank"]) == [1, 2]
    assert (ranking.state_rmse.diff().dropna() >= 0).all()
    assert "us_per_step" not in " ".join(ranking.columns)  # deterministic columns only


def test_quoted_rows_only_where_they_apply(files: dict[str, str]) -> None:
    assert "paper: FlexKalmanNet (quoted)" in files["ds1.md"] and "paper: manual EKF (quoted)" in files["ds1.md"]
    assert "| – | paper: FlexKalmanNet (quoted) |" in files["ds1.md"]  # never ranked
    assert "0.044 | 0.046 | 0.039 | 0.047 | 0.102 | 0.103 | 0.101 | 0.001" in files["ds1.md"]
    assert "(quoted)" not in files["ds2.md"]
    assert "paper: manual EKF (quoted)" in files["ds1.html"]


def test_reference_rows() -> None:
    assert [r.label for r in quoted_rows("ds1")] == ["paper: FlexKalmanNet (quoted)", "paper: manual EKF (quoted)"]
    assert quoted_rows("ds2") == []
    manual = PAPER_ROWS[1]
    assert manual.rmse["wx"] == 0.008 and manual.rmse["rx"] == 0.103
    assert manual.state_rmse == pytest.approx((sum(v * v for v in manual.rmse.values()) / 13) ** 0.5)
    assert "FlexKalmanNet" in manual.citation


def test_index_and_provenance(files: dict[str, str]) -> None:
    assert REGENERATE_COMMAND in files["README.md"]
    assert "[ds1](ds1.md)" in files["README.md"]
    provenance = json.loads(files["provenance.json"])
    assert provenance["cells"] == 8 and provenance["failed_cells"] == []
    assert provenance["scenarios"]["ds1"]["seeds"] == list(range(12))
    assert set(provenance["estimators"]) == {"manual-ekf", "oracle-ekf"}


def test_notes_written_by_people_become_a_section_of_the_index(small_results_dir: Path, files: dict[str, str],
                                                                capsys: pytest.CaptureFixture, tmp_path: Path) -> None:
    from fkn_bench.cli import main
    from fkn_bench.reporting.leaderboard import NOTES_FILE

    assert "## Notes" not in files["README.md"]
    noted = build_leaderboards(ResultStore(small_results_dir).load(), notes="### Finding\n\nA number (`cmd`).\n")
    index = noted["README.md"]
    assert index.index("### Overview") < index.index("## Notes") < index.index("### Finding") < index.index("## Files")
    assert {k: v for k, v in noted.items() if k != "README.md"} == {k: v for k, v in files.items() if k != "README.md"}
    # the command reads them from the results directory
    results = tmp_path / "results"
    import shutil

    shutil.copytree(small_results_dir, results)
    (results / NOTES_FILE).write_text("### Finding\n\nA number (`cmd`).\n")
    assert main(["leaderboard", "--results", str(results), "--out", str(tmp_path / "out")]) == 0
    assert (tmp_path / "out" / "README.md").read_text() == index


def test_results_csv_is_the_deterministic_record(files: dict[str, str]) -> None:
    rows = pd.read_csv(io.StringIO(files["results.csv"]))
    assert "cost" not in set(rows.group)
    assert len(rows) == 8 * 10 * 0 + len(rows)  # parses
    assert list(rows.columns) == ["estimator", "scenario", "seed", "group", "metric", "value", "unit"]


def test_rebuild_is_byte_identical(small_results_dir: Path, tmp_path: Path, files: dict[str, str]) -> None:
    for _ in range(2):  # the second time over its own files (listed in the manifest)
        write_leaderboards(ResultStore(small_results_dir).load(), tmp_path)
        assert {p.name: p.read_text() for p in tmp_path.iterdir() if p.is_file() and not p.name.startswith(".")} == files
    assert sorted(p.name for p in (tmp_path / "figures").iterdir() if not p.name.startswith(".")) == ["comparison-ds1.png"]


def test_failed_estimator_ranks_last(short_ds1: SimulatedSource, test_estimators: None) -> None:
    outcome = run_grid(build_grid(["raising", "manual-ekf"], [short_ds1], range(2)), progress=False)
    files = build_leaderboards(outcome.results)
    ranking = pd.read_csv(io.StringIO(files["ds1.csv"]))
    assert list(ranking.estimator) == ["manual-ekf", "raising"]
    assert pd.isna(ranking["rank"].iloc[1])
    assert "| – | raising |" in files["ds1.md"]
    assert json.loads(files["provenance.json"])["failed_cells"] == ["raising/ds1/seeds-0-1"]


def test_rank_sorts_missing_scores_last() -> None:
    summaries = [{"estimator": "b", "state_rmse": float("nan")}, {"estimator": "c", "state_rmse": 0.2},
                 {"estimator": "a", "state_rmse": 0.2}]
    assert [s["estimator"] for s in rank(summaries)] == ["a", "c", "b"]


def test_table_renderers_escape() -> None:
    table = Table("T <x>", ["a|b", "c"], [["<&>", "1|2"]], notes=["n1", "n2"])
    md = markdown_table(table)
    assert "a\\|b" in md and "1\\|2" in md and "\n\nn1\n\nn2\n" in md
    html = html_table(table)
    assert "&lt;&amp;&gt;" in html and "T &lt;x&gt;" in html


def test_a_run_with_options_is_a_row_named_by_them(small_results_dir: Path) -> None:
    """Issue 34, finding 3: the gated run shows as such, not as plain manual-ekf."""
    from dataclasses import replace

    results = ResultStore(small_results_dir).load()
    gated = [replace(r, key={**r.key, "estimator_options": [["gate", 0.5]]}) for r in results.records
             if r.estimator == "manual-ekf"]
    from fkn_bench.harness import Results

    files = build_leaderboards(Results([*results.records, *gated]))
    ranking = pd.read_csv(io.StringIO(files["ds1.csv"]))
    assert sorted(ranking.estimator) == ["manual-ekf", "manual-ekf (gate=0.5)", "oracle-ekf"]
    assert "| manual-ekf (gate=0.5) |" in files["ds1.md"]


@pytest.mark.parametrize("part", ["settings", "source"])
def test_results_mixing_cut_or_split_for_one_scenario_are_refused(small_results_dir: Path, part: str) -> None:
    from dataclasses import replace

    from fkn_bench.harness import Results

    results = ResultStore(small_results_dir).load()
    first = results.records[0]
    other = {"settings": {**first.key["settings"], "cut": 300}, "source": first.key["source"].replace(":test", ":val")}
    mixed = Results([*results.records[1:], replace(first, key={**first.key, part: other[part]})])
    message = {"settings": r"results mix metric settings for scenario ds1: cut=100 \(cell manual-ekf/ds1/seeds-10-11\) "
                           r"and cut=300 \(cell manual-ekf/ds1/seeds-0-9\); keep one split, cut and scenario",
               "source": r"results mix data \(split or scenario configuration\) for scenario ds1: simulated:ds1:\w+:test "
                         r"\(cell manual-ekf/ds1/seeds-10-11\) and simulated:ds1:\w+:val"}
    with pytest.raises(ValueError, match=message[part]):
        build_leaderboards(mixed)


def test_scenario_names_become_file_names_that_stay_in_the_directory(small_results_dir: Path) -> None:
    from dataclasses import replace

    from fkn_bench.harness import Results

    results = ResultStore(small_results_dir).load()
    renamed = Results(replace(r, scenario={"ds1": "../x y", "ds2": "ds2"}[r.scenario]) for r in results.records)
    files = build_leaderboards(renamed)
    assert {f"%2E.%2Fx%20y.{ext}" for ext in ("md", "html", "csv")} <= set(files)
    assert all("/" not in name for name in files)
    assert "[../x y](%252E.%252Fx%2520y.md)" in files["README.md"]  # a link that finds the file


@pytest.mark.parametrize(("anees", "verdict"), [(12.0, "consistent"), (10.7, "consistent"), (13.5, "overconfident"),
                                                (9.0, "conservative"), (float("nan"), "none"), (None, "none")])
def test_covariance_verdict_reads_the_anees_against_its_bounds(anees, verdict) -> None:  # noqa: ANN001
    assert covariance_verdict({"anees": anees, "anees_bounds": (10.7, 13.4)}) == verdict
