"""``fkn-bench leaderboard``: the committed leaderboards regenerate byte for byte from the committed
results, and the committed figures were drawn from the same numbers; every figure README.md and the
leaderboards show carries the command that draws it; errors for missing results."""

from __future__ import annotations

from pathlib import Path

import re
from urllib.parse import unquote

import pytest

from fkn_bench.cli import main
from fkn_bench.reporting.figures import COMMAND_KEY, FINGERPRINT_KEY, figure_problems, png_text
from fkn_bench.reporting.leaderboard import REGENERATE_COMMAND

REPO = Path(__file__).resolve().parents[2]
LEADERBOARDS = REPO / "leaderboards"


def _files(root: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in root.iterdir() if p.is_file() and not p.name.startswith(".")}


@pytest.mark.slow(seconds=20)  # every committed cell read, every leaderboard and figure redrawn
def test_committed_leaderboards_regenerate_identically(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert (LEADERBOARDS / "results" / "cells").is_dir(), "committed results are missing"
    assert main(["leaderboard", "--results", str(LEADERBOARDS / "results"), "--out", str(tmp_path)]) == 0
    regenerated = _files(tmp_path)
    committed = {k: v for k, v in _files(LEADERBOARDS).items()
                 if not k.startswith(("cross-scenario.", "shift."))}  # --cross's, and the shift table's (issue 39, item 5)
    assert sorted(regenerated) == sorted(committed)
    for name in sorted(committed):
        assert regenerated[name] == committed[name], f"leaderboards/{name} differs from its regeneration"
    figures = sorted(p.name for p in (tmp_path / "figures").iterdir() if not p.name.startswith("."))
    assert "comparison-ds1.png" in figures
    assert sorted(p.name for p in (LEADERBOARDS / "figures").glob("comparison-*.png")) == figures
    for name in figures:  # pixels may differ between machines; the numbers they plot may not
        assert png_text(LEADERBOARDS / "figures" / name).get(FINGERPRINT_KEY) == \
            png_text(tmp_path / "figures" / name)[FINGERPRINT_KEY], \
            f"leaderboards/figures/{name} was drawn from other numbers than leaderboards/results: redraw it with " \
            f"`fkn-bench leaderboard`"
    written = capsys.readouterr().out.split()
    assert len(written) == len(committed) + len(figures)


def _shown_figures() -> dict[Path, str]:
    """Every PNG that README.md and the leaderboards' Markdown link to: ``{path: the file linking it}``."""
    shown = {}
    for page in [REPO / "README.md", *sorted(LEADERBOARDS.glob("*.md"))]:
        for target in re.findall(r"\]\(([^)\s]+\.png)\)", page.read_text(encoding="utf-8")):
            shown.setdefault((page.parent / unquote(target)).resolve(), str(page.relative_to(REPO)))
    return shown


def test_every_figure_shown_names_the_command_that_draws_it() -> None:
    """Issue 39, item 8: leaderboards/figures/comparison-ds1.png, shown in README.md, had been drawn
    from old results and copied in by hand."""
    shown = _shown_figures()
    assert LEADERBOARDS / "figures" / "comparison-ds1.png" in shown
    problems = [f"{problem} (shown in {page})" for path, page in sorted(shown.items()) for problem in figure_problems(path)]
    assert not problems, "\n".join(problems)
    for path in shown:
        if path.name.startswith("comparison-"):  # drawn from results: the fingerprint test above checks the numbers
            assert png_text(path)[COMMAND_KEY] == "fkn-bench leaderboard" and FINGERPRINT_KEY in png_text(path)


def test_committed_leaderboards_cover_every_named_scenario() -> None:
    from fkn_bench.scenarios import scenario_names

    names = _files(LEADERBOARDS)
    for scenario in scenario_names():
        assert {f"{scenario}.md", f"{scenario}.html", f"{scenario}.csv"} <= set(names)
    assert {"cross-scenario.md", "cross-scenario.csv"} <= set(names)
    assert "paper: FlexKalmanNet (quoted)" in (LEADERBOARDS / "ds1.md").read_text()
    assert REGENERATE_COMMAND in (LEADERBOARDS / "README.md").read_text()


def test_missing_results_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["leaderboard", "--results", str(tmp_path / "nothing"), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "not found" in err and "fkn-bench run --all --out" in err
    assert not (tmp_path / "out").exists()


def test_the_default_results_are_found_from_any_directory(tmp_path, monkeypatch) -> None:  # noqa: ANN001
    """Issue 20, item 6: `fkn-bench leaderboard` and `plot --results` default to the checkout's
    leaderboards when the current directory has none."""
    from pathlib import Path

    from fkn_bench.cli.options import default_leaderboards

    checkout = Path(__file__).resolve().parents[2] / "leaderboards"
    monkeypatch.chdir(tmp_path)
    assert default_leaderboards() == checkout
    (tmp_path / "leaderboards").mkdir()
    assert default_leaderboards() == Path("leaderboards")


def test_the_committed_manifest_lists_every_generated_file(capsys: pytest.CaptureFixture) -> None:
    """`fkn-bench leaderboard` (in place) replaces the committed files without --force."""
    import hashlib
    import json

    from fkn_bench.reporting.manifest import MANIFEST

    listed = json.loads((LEADERBOARDS / MANIFEST).read_text())["files"]
    for name, data in _files(LEADERBOARDS).items():
        assert listed.get(name) == hashlib.sha256(data).hexdigest(), name


def test_a_file_fkn_bench_did_not_write_is_never_replaced(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """Issue 34, finding 1: `echo MINE > lb/README.md; fkn-bench run ... --out lb/ov; fkn-bench
    leaderboard --results lb/ov` replaced lb/README.md and lb/results.csv."""
    from fkn_bench.harness import ResultStore, SimulatedSource, build_grid, run_grid
    from fkn_bench.scenarios import get_scenario

    source = SimulatedSource(get_scenario("ds1", n_steps=2000))
    run_grid(build_grid(["manual-ekf"], [source], [0, 1], online_steps=5), store=ResultStore(tmp_path / "ov"),
             progress=False)
    (tmp_path / "README.md").write_text("MINE\n")
    (tmp_path / "results.csv").write_text("MINE too\n")
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(["leaderboard", "--results", str(tmp_path / "ov")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"fkn-bench leaderboard: error: {tmp_path}/README.md exists and fkn-bench did not " \
                                    f"write it" in err and "--force" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == before and (tmp_path / "README.md").read_text() == "MINE\n"
    assert main(["leaderboard", "--results", str(tmp_path / "ov"), "--force"]) == 0
    assert (tmp_path / "README.md").read_text().startswith("# fkn-bench leaderboards")
    (tmp_path / "ds1.md").write_text("edited\n")
    assert main(["leaderboard", "--results", str(tmp_path / "ov")]) == 2
    assert f"{tmp_path}/ds1.md exists and fkn-bench did not write it (or it was edited since" in capsys.readouterr().err


def test_shift_and_cross_options_are_checked_before_any_work(tmp_path, capsys) -> None:  # noqa: ANN001
    from fkn_bench.cli import main

    assert main(["leaderboard", "--shift", "--cross", "--out", str(tmp_path)]) == 2
    assert "--cross, --shift and --novelty make different tables" in capsys.readouterr().err
    assert main(["leaderboard", "--shift", "--novelty", "tumble-flip", "--out", str(tmp_path)]) == 2
    assert main(["leaderboard", "--novelty", "tumble-flip", "--seeds", "5", "--results", str(tmp_path)]) == 2
    assert "--novelty reads the stored results' seeds" in capsys.readouterr().err
    assert main(["leaderboard", "--novelty", "tumble-flip", "--results", str(tmp_path / "none")]) == 2
    assert "results directory not found" in capsys.readouterr().err
    assert main(["leaderboard", "--seeds", "5", "--out", str(tmp_path)]) == 2
    assert "--seeds goes with --cross or --shift" in capsys.readouterr().err
    assert main(["leaderboard", "--shift", "--seeds", "1", "--out", str(tmp_path)]) == 2
    (tmp_path / "shift.md").write_text("MINE\n")  # a file fkn-bench did not write is never replaced
    assert main(["leaderboard", "--shift", "--seeds", "2", "--out", str(tmp_path)]) == 2
    assert (tmp_path / "shift.md").read_text() == "MINE\n" and not (tmp_path / "shift.csv").exists()


@pytest.mark.slow(seconds=10)  # every committed cell read, the test and training episodes' axes generated
def test_novelty_separates_memory_from_estimation_on_the_committed_tumble_flip(capsys: pytest.CaptureFixture) -> None:
    assert main(["leaderboard", "--novelty", "tumble-flip", "--results", str(LEADERBOARDS / "results")]) == 0
    out = capsys.readouterr().out
    assert "far: > 45 deg (9 episodes)" in out
    ratio = {line.split("|")[1].strip(): float(line.split("|")[4]) for line in out.splitlines()
             if line.startswith("| ") and not line.startswith("| estimator")}
    # the learned noise generalises to spin axes never trained on; Split-KalmanNet's learned gain does not
    assert ratio["manual-ekf"] < 1.25 and ratio["flexkalmannet"] < 1.25
    assert ratio["split-kalmannet"] > 5
