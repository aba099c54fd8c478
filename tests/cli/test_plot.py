"""``fkn-bench plot``: PNG figures of a short run and comparison charts; exit codes."""

from __future__ import annotations

from pathlib import Path

import pytest

from fkn_bench.cli import main
from fkn_bench.scenarios import registry

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(autouse=True)
def isolated_registry(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))


@pytest.fixture
def tiny(tmp_path: Path) -> str:
    path = tmp_path / "tiny.toml"
    path.write_text('[scenario.tiny]\nbase = "ds1"\nn_steps = 2000\n')
    return str(path)


def test_run_figures_and_comparison(tmp_path: Path, tiny: str, capsys: pytest.CaptureFixture) -> None:
    results = tmp_path / "results"
    assert main(["run", "--estimator", "manual-ekf", "--estimator", "oracle-ekf", "--scenario", "tiny",
                 "--scenario-file", tiny, "--seeds", "2", "--out", str(results), "--no-progress"]) == 0
    capsys.readouterr()
    out = tmp_path / "figures"
    assert main(["plot", "--estimator", "manual-ekf", "--scenario", "tiny", "--scenario-file", tiny, "--seed", "1",
                 "--steps", "80", "--out", str(out), "--results", str(results)]) == 0
    printed = capsys.readouterr().out.split()
    names = sorted(Path(p).name for p in printed)
    assert names == sorted([
        "manual-ekf-tiny-seed1-states.png", "manual-ekf-tiny-seed1-uncertainty.png",
        "manual-ekf-tiny-seed1-errors.png", "comparison-tiny.png",
    ])
    for path in printed:
        assert Path(path).read_bytes()[:8] == PNG_MAGIC
    # issue 39, item 8: each names the command that draws it; the chart holds the numbers it plots
    from fkn_bench.harness import ResultStore
    from fkn_bench.reporting.figures import COMMAND_KEY, figure_problems, png_text
    from fkn_bench.reporting.leaderboard import ranked_summaries
    from fkn_bench.reporting.plots import comparison_data

    states = png_text(out / "manual-ekf-tiny-seed1-states.png")[COMMAND_KEY]
    assert states == ("fkn-bench plot --estimator manual-ekf --scenario tiny --seed 1 --split test --cut 100 --steps 80 "
                      f"--scenario-file={tiny}")
    data = comparison_data("tiny", ranked_summaries(ResultStore(results).load(), "tiny"))
    assert figure_problems(out / "comparison-tiny.png", data) == []
    assert png_text(out / "comparison-tiny.png")[COMMAND_KEY] == f"fkn-bench plot --results {results} --scenario-file={tiny}"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--estimator", "nope"], "valid estimators"),
        (["--scenario", "nope"], "valid scenarios"),
        (["--steps", "1"], "--steps"),
        (["--seed", "-1"], "--seed"),
        (["--results", "/nonexistent/results"], "not found"),
    ],
)
def test_usage_errors(tmp_path: Path, args: list[str], message: str, capsys: pytest.CaptureFixture) -> None:
    assert main(["plot", "--out", str(tmp_path), *args]) == 2
    assert message in capsys.readouterr().err
