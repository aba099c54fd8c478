"""``fkn-bench reproduce --quick`` end to end (report files, tables, determinism), and the report
and differences generators on their own."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from fkn_bench.cli import main
from fkn_bench.reporting.reference import PAPER_LEARNED_STD, PAPER_ROWS, PAPER_TRAINING_RESULTS
from fkn_bench.reproduce.report import Bullets, FigureRef, Heading, Paragraph, Table, render_html, render_markdown
from fkn_bench.reproduce.tables import TIMING_COLUMNS
from fkn_bench.types import STATE_NAMES

pytestmark = pytest.mark.slow(seconds=20)  # two quick reproductions (training, evaluation, figures)

TABLES = ("hyperparameters", "training_results", "learned_std", "rmse_learned_vs_manual", "cross_dataset", "robustness")
FIGURES = (
    "training_loss_ds2", "parameters_ds2", "training_loss_ds1", "parameters_ds1", "states_ds1", "omega_uncertainty_ds1",
    "states_ds1_noise5x", "states_ds1_gap100", "states_ds2", "states_ds1_params_on_ds2", "states_ds2_params_on_ds1",
)


def _quick(out: Path, *extra: str) -> None:
    assert main(["reproduce", "--quick", "--seeds", "3", "--out", str(out), "--no-progress", *extra]) == 0


def _table(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def _without_timing(path: Path) -> list[list[str]]:
    with path.open(newline="") as fh:
        rows = list(csv.reader(fh))
    keep = [i for i, name in enumerate(rows[0]) if name not in TIMING_COLUMNS]
    return [[row[i] for i in keep] for row in rows]


@pytest.fixture(scope="module")
def quick_report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("reproduce") / "report"
    _quick(out)
    return out


def test_quick_run_writes_the_report(quick_report: Path) -> None:
    for name in ("index.md", "index.html", "results.json"):
        assert (quick_report / name).is_file(), name
    for name in TABLES:
        assert (quick_report / "tables" / f"{name}.csv").is_file(), name
    for name in FIGURES:
        data = (quick_report / "figures" / f"{name}.png").read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n", name
    for dataset in ("ds1", "ds2"):
        assert (quick_report / "training" / dataset / "parameters.json").is_file()
    markdown = (quick_report / "index.md").read_text()
    assert "QUICK RUN" in markdown and "Differences from the paper" in markdown
    for name in FIGURES:
        assert f"figures/{name}.png" in markdown
    html = (quick_report / "index.html").read_text()
    assert html.startswith("<!DOCTYPE html>") and html.count("<table>") == len(TABLES) and "QUICK RUN" in html
    results = json.loads((quick_report / "results.json").read_text())
    assert results["quick"] is True and results["eval_seeds"] == 3
    assert results["config"]["hidden"] == 32 and results["config"]["epochs"] == 3


def test_tables_put_the_quoted_paper_values_beside_ours(quick_report: Path) -> None:
    training = _table(quick_report / "tables" / "training_results.csv")
    assert [(r["data set"], r["source"]) for r in training] == [
        ("DS1", "ours"), ("DS1", "paper (quoted)"), ("DS2", "ours"), ("DS2", "paper (quoted)")]
    assert training[1]["best val. epoch"] == str(PAPER_TRAINING_RESULTS["ds1"].best_val_epoch)
    assert training[3]["test RMSE"] == f"{PAPER_TRAINING_RESULTS['ds2'].test_rmse:.4f}"
    assert 1 <= int(training[0]["epochs run"]) <= 3

    stds = _table(quick_report / "tables" / "learned_std.csv")
    assert len(stds) == 20
    by_name = {r["parameter"]: r for r in stds}
    assert by_name["sigma_R_qw"]["paper DS1 (quoted)"] == f"{PAPER_LEARNED_STD['ds1']['sigma_R_qw']:.6f}"
    assert by_name["sigma_Q_rx"]["manual tuning"] == "0.000100"
    assert all(float(r["ours DS1"]) > 0 for r in stds)

    rmse = _table(quick_report / "tables" / "rmse_learned_vs_manual.csv")
    assert [r["variable"] for r in rmse] == [*STATE_NAMES, "13-state"]
    paper = {row.label: row.rmse for row in PAPER_ROWS}["paper: FlexKalmanNet (quoted)"]
    assert all(r["paper learned (quoted)"] == f"{paper[r['variable']]:.3f}" for r in rmse[:13])
    for row in rmse:
        assert 0 < float(row["ours manual"]) < 0.2

    cross = _table(quick_report / "tables" / "cross_dataset.csv")
    pairs = {(r["parameters"], r["run on"]) for r in cross}
    assert {("learned DS1", "ds2"), ("learned DS2", "ds1"), ("manual tuning", "ds1")} <= pairs
    robust = {(r["parameters"], r["run on"]) for r in _table(quick_report / "tables" / "robustness.csv")}
    assert {("learned DS1", "ds1-noise5x"), ("learned DS1", "ds1-gap100")} <= robust


def test_differences_are_generated_from_the_numbers(quick_report: Path) -> None:
    results = json.loads((quick_report / "results.json").read_text())
    bullets = results["differences"]
    assert bullets[0].startswith("**QUICK RUN.**")
    learned = next(e for e in results["evaluations"] if e["estimator"] == "learned-ds1" and e["scenario"] == "ds1")
    manual = next(e for e in results["evaluations"] if e["estimator"] == "manual" and e["scenario"] == "ds1")
    text = "\n".join(bullets)
    assert f"{learned['state_rmse']:.4f} learned vs {manual['state_rmse']:.4f} manual" in text
    assert "Cross-data-set runs" in text and "Robustness" in text and "Settling" in text


def test_two_quick_runs_give_identical_tables(quick_report: Path, tmp_path: Path) -> None:
    # the second run without figures (they are drawn from the same trained models and traces and
    # feed no table): the tables and results must not depend on them either
    again = tmp_path / "again"
    _quick(again, "--no-figures")
    assert not (again / "figures").exists() or not any((again / "figures").iterdir())
    for name in TABLES:
        path = Path("tables") / f"{name}.csv"
        assert _without_timing(again / path) == _without_timing(quick_report / path), name
    first = json.loads((quick_report / "results.json").read_text())
    second = json.loads((again / "results.json").read_text())
    assert first["evaluations"] == second["evaluations"]
    for dataset in ("ds1", "ds2"):
        assert first["training"][dataset]["learned_std"] == second["training"][dataset]["learned_std"]


def test_usage_errors_exit_with_code_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["reproduce", "--quick", "--seeds", "0", "--out", str(tmp_path)]) == 2
    assert "--seeds" in capsys.readouterr().err
    assert main(["reproduce", "--quick", "--config", str(tmp_path / "missing.toml"), "--out", str(tmp_path)]) == 2
    assert "not found" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text("hiddn = 3\n")
    assert main(["reproduce", "--quick", "--config", str(bad), "--out", str(tmp_path)]) == 2
    assert "hiddn" in capsys.readouterr().err


def test_a_full_disk_ends_the_quick_run_in_one_line(quick_report: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 34, finding 4: on a full disk ``reproduce --quick`` ended in torch's "unexpected pos
    81792 vs 81684" traceback; now one line naming the file and the space, exit 2, and nothing torn
    left (after the first epoch: ``quick_report`` has built the training data already)."""
    import errno

    import torch

    def full_disk(document: object, path: Path, *args: object, **kwargs: object) -> None:
        Path(path).write_bytes(b"PK\x03\x04 torn")  # part of the checkpoint, then the disk is full
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(torch, "save", full_disk)
    out = tmp_path / "report"
    assert main(["reproduce", "--quick", "--seeds", "1", "--out", str(out), "--no-progress"]) == 2
    error = capsys.readouterr().err.strip().splitlines()
    checkpoint = out / "training" / "ds1" / "checkpoint.pt"
    assert len(error) == 1 and error[0].startswith("fkn-bench reproduce: error: no space left on the device to write "
                                                   f"{checkpoint} ("), error
    assert not checkpoint.exists() and not list(out.rglob("*.tmp"))


def test_markdown_and_html_render_the_same_blocks() -> None:
    table = Table("A <table>", ("name", "value"), (("a|b", "1.0"), ("**x**", "2")), ("note with `code`",), name="t")
    blocks = [Heading("Title", 1), Paragraph("Text with **bold** & `code`."), Bullets(("one", "two")), table,
              FigureRef("figures/f.png", "A figure")]
    markdown = render_markdown(blocks)
    assert "# Title" in markdown and "| a\\|b | 1.0 |" in markdown and "![A figure](figures/f.png)" in markdown
    html = render_html(blocks, title="T")
    assert "<strong>bold</strong> &amp; <code>code</code>" in html
    assert "A &lt;table&gt;" in html and '<img src="figures/f.png"' in html
    assert table.to_csv().splitlines() == ["name,value", "a|b,1.0", "**x**,2"]
    with pytest.raises(ValueError, match="cells"):
        Table("bad", ("a", "b"), (("only one",),), name="bad")
