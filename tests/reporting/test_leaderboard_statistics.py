"""Leaderboards, issue 39: 95% intervals and paired-test ties (item 6), the prior families leading
the index (item 4's layout), and comparison charts that carry the numbers they plot (item 8)."""

from __future__ import annotations

import io
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fkn_bench.harness import Results, ResultStore
from fkn_bench.reporting.figures import COMMAND_KEY, FINGERPRINT_KEY, figure_problems, png_bytes, png_text
from fkn_bench.reporting.leaderboard import (LEADERBOARD_COMMAND, build_figures, build_leaderboards, rank_numbers,
                                           ranked_summaries, tie_tests, write_leaderboards)
from fkn_bench.reporting.manifest import ForeignFileError
from fkn_bench.reporting.plots import comparison_chart, comparison_data
from fkn_bench.reporting.reference import quoted_rows


def _summary(name: str, scores: list[float], mean: float | None = None) -> dict:
    finite = [v for v in scores if math.isfinite(v)]
    return {"estimator": name, "seeds": list(range(len(scores))), "state_rmse_by_seed": scores,
            "state_rmse": mean if mean is not None else (float(np.mean(finite)) if finite else float("nan"))}


def test_adjacent_ranks_the_paired_test_cannot_separate_share_a_rank() -> None:
    a = [0.010 + 0.001 * i for i in range(8)]
    b = [v + (1e-5 if i % 2 else -1e-5) * (1 + i) for i, v in enumerate(a)]  # not separable from a
    c = [v + 0.005 for v in a]  # worse on every episode: exact two-sided p = 2 / 2**8
    d = [v + 0.001 for v in c[:-1]] + [float("nan")]  # a diverged episode: no test, no tie
    ranked = [_summary("a", a), _summary("b", b), _summary("c", c), _summary("d", d), _summary("e", [float("nan")] * 8)]
    tests = tie_tests(ranked)
    assert tests[0] is None and tests[4] is None  # the first, and one without a score
    assert tests[1].tied and tests[1].episodes == 8
    assert not tests[2].tied and tests[2].pvalue == pytest.approx(2 / 2**8)
    assert tests[3].pvalue is None and not tests[3].tied
    assert rank_numbers(ranked, tests) == [1, 1, 3, 4, None]


def _prior(results: Results) -> Results:
    """ds2's cells relabelled as the prior family spin (tagged "prior" in their stored configuration)."""
    def relabel(record):  # noqa: ANN001, ANN202
        if record.scenario != "ds2":
            return record
        source = {**record.source, "config": {**record.source["config"], "name": "spin", "tags": ["prior"]}}
        rows = record.rows.assign(scenario="spin")
        return replace(record, scenario="spin", source=source, rows=rows)

    return Results([relabel(r) for r in results.records])


def test_the_prior_families_lead_and_each_section_ranks_its_own(small_results_dir: Path) -> None:
    results = ResultStore(small_results_dir).load()
    plain = build_leaderboards(results)["README.md"]
    prior_part = plain[plain.index("## Prior families"):plain.index("## The paper's scenarios")]
    assert "No results for these scenarios" in prior_part  # a section without results says so
    index = build_leaderboards(_prior(results))["README.md"]
    prior, paper = index.index("## Prior families"), index.index("## The paper's scenarios")
    assert prior < index.index("| estimator | spin |") < paper < index.index("| estimator | ds1 |")
    assert "| estimator | ds1 | spin |" not in index and "No results for these scenarios" not in index
    assert prior < index.index("figures/comparison-spin.png") < paper < index.index("figures/comparison-ds1.png")
    assert "train and test share one trajectory" in index and "Wilcoxon signed-rank" in index
    assert "Test episodes (seeds) per estimator and scenario: 12." in index


def test_each_cell_has_its_interval_and_the_test_against_the_row_above(small_results_dir: Path) -> None:
    results = ResultStore(small_results_dir).load()
    files = build_leaderboards(results)
    ranking = pd.read_csv(io.StringIO(files["ds1.csv"]))
    assert (ranking.state_rmse_ci_low < ranking.state_rmse).all() and (ranking.state_rmse < ranking.state_rmse_ci_high).all()
    assert pd.isna(ranking.p_vs_above.iloc[0]) and 0.0 <= ranking.p_vs_above.iloc[1] <= 1.0
    tied = bool(ranking.tied_with_above.iloc[1])
    assert tied == (ranking.p_vs_above.iloc[1] >= 0.05) and list(ranking["rank"]) == ([1, 1] if tied else [1, 2])
    summary = ranked_summaries(results, "ds1")[0]
    low, high = summary["state_rmse_ci"]
    assert f"{summary['state_rmse']:.5f} [{low:.5f}, {high:.5f}]" in files["ds1.md"]
    assert "95% confidence interval" in files["ds1.md"] and "12 test episodes" in files["ds1.md"]
    assert f"**{summary['state_rmse']:.5f} ±" in files["README.md"]  # the overview: mean ± half width, best bold


def test_a_non_finite_episode_gives_no_interval_and_no_tie(small_results_dir: Path) -> None:
    results = ResultStore(small_results_dir).load()

    def diverge(record):  # noqa: ANN001, ANN202
        if (record.estimator, record.scenario) != ("manual-ekf", "ds1") or 3 not in record.seeds:
            return record
        rows = record.rows.copy()
        rows.loc[(rows.seed == 3) & (rows.group == "state") & (rows.metric == "rmse"), "value"] = np.inf
        return replace(record, rows=rows)

    files = build_leaderboards(Results([diverge(r) for r in results.records]))
    row = pd.read_csv(io.StringIO(files["ds1.csv"])).set_index("estimator").loc["manual-ekf"]
    assert pd.isna(row.state_rmse_ci_low) and pd.isna(row.p_vs_above) and pd.isna(row.tied_with_above)
    assert math.isfinite(row.state_rmse) and not pd.isna(row["rank"])  # still ranked, by its finite seeds
    assert "[n/a] | n/a |" in files["ds1.md"] and "(CI n/a)" in files["README.md"]
    assert not any(cell.strip().lower() in ("nan", "[nan, nan]") or "nan [" in cell.lower()
                   for line in files["ds1.md"].splitlines() if line.startswith("|") for cell in line.split("|"))


def test_a_comparison_chart_carries_the_numbers_it_plots(small_results_dir: Path, tmp_path: Path) -> None:
    results = ResultStore(small_results_dir).load()
    paths = write_leaderboards(results, tmp_path)
    figure = tmp_path / "figures" / "comparison-ds1.png"
    assert figure in paths
    data = comparison_data("ds1", ranked_summaries(results, "ds1"), quoted_rows("ds1"))
    assert figure_problems(figure, data) == []  # recomputed from the results: the same fingerprint
    assert png_text(figure)[COMMAND_KEY] == LEADERBOARD_COMMAND
    assert set(build_figures(results)) == {"comparison-ds1.png"}
    # a chart drawn from other numbers (the old comparison-ds1.png: adaptive filters before re-tuning)
    other = {**data, "estimators": [{**row, "mean": row["mean"] * 1.5} for row in data["estimators"]]}
    figure.write_bytes(png_bytes(comparison_chart(other), command=LEADERBOARD_COMMAND, data=other, dpi=30))
    (problem,) = figure_problems(figure, data)
    assert "drawn from other numbers" in problem and f"redraw it with: {LEADERBOARD_COMMAND}" in problem
    # a chart without its text chunks (copied in by hand)
    from fkn_bench.plotting import save_png

    save_png(comparison_chart(data), figure, dpi=30)
    assert FINGERPRINT_KEY not in png_text(figure)
    problems = figure_problems(figure, data)
    assert len(problems) == 2 and "names the command" in problems[0] and "missing" in problems[1]
    assert figure_problems(tmp_path / "none.png") == [f"{tmp_path / 'none.png'}: missing"]


def test_a_figure_fkn_bench_did_not_write_is_refused_before_anything_is_written(small_results_dir: Path,
                                                                                tmp_path: Path) -> None:
    (tmp_path / "figures").mkdir()
    (tmp_path / "figures" / "comparison-ds1.png").write_bytes(b"mine")
    with pytest.raises(ForeignFileError, match="comparison-ds1.png exists and fkn-bench did not write it"):
        write_leaderboards(ResultStore(small_results_dir).load(), tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figures"]
    assert (tmp_path / "figures" / "comparison-ds1.png").read_bytes() == b"mine"
