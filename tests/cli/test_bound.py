"""``fkn-bench bound``: a scenario's posterior Cramér-Rao bound, the bounds of stored results with
each estimator's efficiency, the bound-over-time figure; one-line usage errors."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from fkn_bench.cli import main
from fkn_bench.metrics import GROUPS

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _rows(text: str) -> dict[str, list[str]]:
    """The bound table's rows by their first word."""
    return {line.split()[0]: line.split()[1:] for line in text.splitlines() if line.split()}


def test_scenario_bound_prints_every_group_and_the_prior(capsys: pytest.CaptureFixture) -> None:
    assert main(["bound", "--scenario", "spin", "--seeds", "2"]) == 0
    out = capsys.readouterr().out
    rows = _rows(out)
    for name in ("13-state", *GROUPS):
        mean, error = float(rows[name][0]), float(rows[name][1])
        assert math.isfinite(mean) and mean > 0 and math.isfinite(error) and error >= 0, (name, rows[name])
    assert rows["attitude"][-1] == "deg" and rows["omega"][-1] == "rad/s"
    assert "2 episodes of the test split (seeds 0-1), scored from step 100" in out
    assert "prior (stated by the scenario):" in out and "rate: magnitude log-uniform" in out


@pytest.fixture(scope="module")
def spin_results(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """manual-ekf on seeds 0-1 of ``spin`` shortened to 400 steps (its own name: the stored source
    holds the configuration, so the bound needs no scenario file), stored."""
    root = tmp_path_factory.mktemp("results")
    spec = root.parent / "short.toml"
    spec.write_text('[scenario.spin]\nbase = "spin"\nn_steps = 400\noverride = true\n', encoding="utf-8")
    assert main(["run", "--estimator", "manual-ekf", "--scenario", "spin", "--scenario-file", str(spec), "--seeds", "2",
                 "--out", str(root), "--no-progress"]) == 0
    return root


def test_results_store_the_bound_and_print_efficiencies(spin_results: Path, capsys: pytest.CaptureFixture) -> None:
    capsys.readouterr()
    assert main(["bound", "--results", str(spin_results)]) == 0
    captured = capsys.readouterr()
    path = spin_results / "bounds" / "spin.json"
    assert path.is_file() and "spin: computing the bound of 2 episodes" in captured.err
    rows = {line.split()[0]: line for line in captured.out.splitlines() if line.split()}
    assert rows["bound"].split()[2] == "2"  # "bound (PCRB)  2  mean ± se ..."
    cells = rows["manual-ekf"].split()[1:]  # runs, then "RMSE (efficiency)" per score
    assert cells[0] == "2"
    efficiencies = [float(cell.strip("()")) for cell in cells[2::2]]
    assert len(efficiencies) == 1 + len(GROUPS)
    assert all(0 < e <= 1.05 for e in efficiencies), efficiencies
    written = path.stat().st_mtime_ns
    assert main(["bound", "--results", str(spin_results), "--scenario", "spin"]) == 0
    captured = capsys.readouterr()
    assert "spin: the stored bound is up to date" in captured.err and "computing" not in captured.err
    assert path.stat().st_mtime_ns == written
    assert "manual-ekf" in captured.out


def test_plot_draws_the_bound_against_an_estimator(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from fkn_bench.reporting.figures import COMMAND_KEY, png_text

    path = tmp_path / "figures" / "spin-bound.png"
    assert main(["bound", "--scenario", "spin", "--seeds", "2", "--plot", str(path), "--estimator", "manual-ekf"]) == 0
    assert f"figure: {path}" in capsys.readouterr().out
    assert path.read_bytes()[:8] == PNG_MAGIC
    assert png_text(path)[COMMAND_KEY] == ("fkn-bench bound --scenario spin --seeds 2 --plot spin-bound.png "
                                           "--estimator manual-ekf")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--scenario", "nope"], "valid scenarios"),
        (["--plot", "x.png"], "--plot draws one scenario's bound: give --scenario NAME"),
        (["--scenario", "spin", "--seeds", "0"], "--seeds must be a positive integer"),
        (["--scenario", "spin", "--cut", "3000"], "--cut must be below"),
        (["--scenario", "spin", "--estimator", "manual-ekf"], "--estimator goes with --plot"),
        (["--scenario", "spin", "--plot", "x.png", "--estimator", "nope"], "valid estimators"),
        (["--scenario", "spin", "--force"], "--force goes with --results"),
        ([], "give --scenario NAME"),
        (["--results", "/nonexistent/results"], "not found"),
        (["--results", "/nonexistent/results", "--seeds", "3"], "--seeds goes with --scenario alone"),
    ],
)
def test_usage_errors(tmp_path: Path, args: list[str], message: str, capsys: pytest.CaptureFixture) -> None:
    assert main(["bound", *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("fkn-bench bound: error: ") and message in err, err
    assert err.count("\n") == 1 and "Traceback" not in err


def test_results_without_a_named_scenario(spin_results: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["bound", "--results", str(spin_results), "--scenario", "tumble"]) == 2
    assert "no results for scenario tumble" in capsys.readouterr().err
