"""README.md stays true: its leaderboard excerpt is copied from the committed leaderboard it names
(``Excerpt of [`leaderboards/<scenario>.md`]``: the same estimators in the same order with the same
numbers), its training-seed table from the leaderboards' index, and the test command that ``.ci/run`` extracts is the one README shows."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"


def _markdown_table_after(text: str, marker: str) -> list[dict[str, str]]:
    """Rows (header -> cell) of the first Markdown table after ``marker``."""
    lines = text[text.index(marker):].splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("|"))
    table = []
    for line in lines[start:]:
        if not line.startswith("|"):
            break
        table.append([cell.strip() for cell in line.strip().strip("|").split("|")])
    header, rows = table[0], table[2:]
    return [dict(zip(header, row)) for row in rows]


def _column(header: str, row: dict[str, str]) -> str:
    """The leaderboard's name of README column ``header``: the same, or without README's added
    explanation in brackets (``ANEES (12 if consistent)``)."""
    return header if header in row else re.sub(r"\s*\(.*\)$", "", header)


def test_leaderboard_excerpt_matches_the_committed_leaderboard_it_names() -> None:
    text = README.read_text()
    excerpt = _markdown_table_after(text, "Excerpt of")
    (name,) = re.findall(r"Excerpt of\s+\[`leaderboards/([\w-]+\.md)`\]", text)
    committed = _markdown_table_after((REPO / "leaderboards" / name).read_text(), "## Ranking")
    by_estimator = {row["estimator"]: row for row in committed}
    assert excerpt, "README has no leaderboard excerpt"
    ranked = [row["estimator"] for row in committed if row["rank"] != "–"]
    shown = [row["estimator"] for row in excerpt if row["rank"] != "–"]
    assert shown == ranked[: len(shown)], f"README's excerpt must show the top of the {name} ranking in order"
    for row in excerpt:
        assert row["estimator"] in by_estimator, f"{row['estimator']} is not on leaderboards/{name}"
        committed_row = by_estimator[row["estimator"]]
        for header, value in row.items():
            assert committed_row[_column(header, committed_row)] == value, (
                f"README excerpt, {row['estimator']}, {header}: {value} but leaderboards/{name} has "
                f"{committed_row[_column(header, committed_row)]} (copy the regenerated table)"
            )


def test_training_seed_table_is_copied_from_the_leaderboards() -> None:
    """README's training-seed table: every trained estimator of the leaderboards' table, each shown
    cell as the leaderboards have it (README may show fewer scenarios)."""
    shown = _markdown_table_after(README.read_text(), "copied from the leaderboards' training-seed table")
    committed = _markdown_table_after((REPO / "leaderboards" / "README.md").read_text(), "### Spread over training seeds")
    by_estimator = {row["estimator"]: row for row in committed}
    assert [row["estimator"] for row in shown] == list(by_estimator), "README must list the same estimators in order"
    for row in shown:
        for header, value in row.items():
            assert by_estimator[row["estimator"]].get(header) == value, (
                f"README training-seed table, {row['estimator']}, {header}: {value} but leaderboards/README.md has "
                f"{by_estimator[row['estimator']].get(header)} (copy the regenerated table)")


def test_ci_runs_the_readme_test_command() -> None:
    awk = re.search(r"command=\$\(awk '([^']*)' README.md\)", (REPO / ".ci" / "run").read_text())
    assert awk, ".ci/run no longer extracts the command with awk"
    extracted = subprocess.run(["awk", awk.group(1), str(README)], capture_output=True, text=True, check=True).stdout
    assert extracted.strip() == ('python -m pip install torch==2.13.0 -e ".[dev]" && fkn-bench bench compile '
                                 '&& python -m pytest && fkn-bench bench gate --trips')


def test_add_your_estimator_example_registers_a_conforming_estimator(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """The code block of "Add your estimator" runs as shown: the estimator it registers is built
    by the registry and passes the input-rule check."""
    from fkn_bench.estimators import make_estimator, registry
    from fkn_bench.estimators.conformance import check_input_rules

    text = README.read_text()
    section = text[text.index("### Add your estimator"):]
    code = re.search(r"```python\n(.*?)```", section, flags=re.S)
    assert code is not None, "no python block in README's 'Add your estimator'"
    registry.estimator_names()  # built-ins loaded first; the example's entry is removed afterwards
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    exec(compile(code.group(1), "README.md", "exec"), {})
    estimator = make_estimator("my-filter")
    assert estimator.name == "my-filter"
    check_input_rules(estimator)


def test_add_your_process_model_example_registers_a_model_the_filters_run(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """The code block of "Add your process model" runs as shown: a Kalman estimator on the model it
    registers decays the velocity as the block says."""
    import numpy as np

    from fkn_bench.estimators import KalmanEstimator
    from fkn_bench.models import registry

    text = README.read_text()
    section = text[text.index("### Add your process model"):]
    code = re.search(r"```python\n(.*?)```", section, flags=re.S)
    assert code is not None, "no python block in README's 'Add your process model'"
    registry.model_names()
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    exec(compile(code.group(1), "README.md", "exec"), {})
    model = KalmanEstimator(model="damped-velocity").filter.model
    x = model.prior_state(1, np.float64)
    x[:, 10:13] = 1.0
    np.testing.assert_allclose(model.predict(x, 2.0)[0, 10:13], np.exp(-0.1))


def test_readme_settings_of_the_quick_runs_are_the_codes() -> None:
    """The figures README quotes about the quick runs come from the code (issue 20, item 3):
    `reproduce --quick` (a 2x32 network, 3 epochs, 5 seeds) and the quick sweep space's fixed
    values (`epochs = 4`, `episodes = 1`, `patience = 4`) and FlexKalmanNet's defaults README
    gives for a full training (100 epochs, 4 episodes, patience 20)."""
    import tomllib

    from fkn_bench.flexkalmannet.config import FlexKalmanNetConfig
    from fkn_bench.reproduce.pipeline import QUICK_EVAL_SEEDS, QUICK_OVERRIDES

    text = " ".join(README.read_text().split())
    quick = QUICK_OVERRIDES
    assert (f"`--quick` runs the same pipeline with a {quick['layers']}x{quick['hidden']} network, "
            f"{quick['epochs']} epochs and {QUICK_EVAL_SEEDS} seeds") in text
    fixed = tomllib.loads((REPO / "fkn_bench" / "sweep" / "spaces" / "quick.toml").read_text())["fixed"]
    assert f"(`epochs = {fixed['epochs']}`, `episodes = {fixed['episodes']}`, `patience = {fixed['patience']}`" in text
    defaults = FlexKalmanNetConfig()
    assert f"(the defaults are {defaults.epochs} epochs, {defaults.episodes} episodes, patience {defaults.patience})" in text
