"""README's worked example of external estimates runs as written: the ``bash`` block after the
marker ``<!-- example: external estimates -->`` (each ``fkn-bench`` line, in a fresh directory),
and its table has the external row beside the estimator's."""

from __future__ import annotations

import shlex
from pathlib import Path

import pytest

from fkn_bench.cli import main

README = Path(__file__).resolve().parents[2] / "README.md"
MARKER = "<!-- example: external estimates -->"


def _commands() -> list[list[str]]:
    text = README.read_text()
    assert MARKER in text, f"README.md lost its {MARKER} block"
    block = text[text.index(MARKER):].split("```bash\n", 1)[1].split("```", 1)[0]
    return [shlex.split(line, comments=True) for line in block.splitlines() if line.startswith("fkn-bench ")]


def test_the_readme_external_estimates_example_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    commands = _commands()
    assert any("--estimate-topic" in c or "--estimate" in c for c in commands), "the example scores no external estimate"
    monkeypatch.chdir(tmp_path)
    for command in commands:
        assert main(command[1:]) == 0, " ".join(command)
    out = capsys.readouterr().out
    assert "external:/loc/pose" in out
