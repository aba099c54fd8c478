"""``fkn-bench`` itself: a bare call lists the commands; an unknown one is a usage error."""

from __future__ import annotations

import pytest

from fkn_bench.cli import main


def test_bare_call_prints_the_commands(capsys: pytest.CaptureFixture) -> None:
    assert main([]) == 0
    out = capsys.readouterr().out
    for command in ("run", "train", "leaderboard", "bench", "record", "reproduce", "sweep"):
        assert f"    {command}" in out


def test_unknown_command_is_a_usage_error(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["nonsense"])
    assert exit_info.value.code == 2
    assert "invalid choice" in capsys.readouterr().err
