"""Size limits: work that would exceed the memory limit is refused before it allocates, naming
what was asked, the limit and how to raise it (fkn_bench.limits)."""

from __future__ import annotations

from pathlib import Path

import pytest

from fkn_bench.cli import main
from fkn_bench.envs import generate_episodes
from fkn_bench.limits import GIB, MEMORY_LIMIT_VARIABLE, SizeLimitError, check_memory, memory_limit_bytes


def test_the_limit_is_half_the_memory_or_the_variable(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(MEMORY_LIMIT_VARIABLE, raising=False)
    default = memory_limit_bytes()
    assert 0 < default
    monkeypatch.setenv(MEMORY_LIMIT_VARIABLE, "1.5")
    assert memory_limit_bytes() == int(1.5 * GIB)
    check_memory(GIB, "one GiB", "less")  # under the limit: nothing happens
    with pytest.raises(SizeLimitError, match=rf"two GiB would need about 2 GiB of memory, over the limit of 1.5 GiB \({MEMORY_LIMIT_VARIABLE}\); ask for less"):
        check_memory(2 * GIB, "two GiB", "less")
    for bad in ("lots", "-1", "inf", "nan"):
        monkeypatch.setenv(MEMORY_LIMIT_VARIABLE, bad)
        with pytest.raises(SizeLimitError, match=f"{MEMORY_LIMIT_VARIABLE} must be a positive number of GiB"):
            memory_limit_bytes()


def test_generation_over_the_limit_is_refused_before_it_allocates(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(MEMORY_LIMIT_VARIABLE, "0.001")
    with pytest.raises(SizeLimitError, match=r"generating 10 episode\(s\) of 16000 steps of scenario ds1 would need about"):
        generate_episodes("ds1", 10)
    assert generate_episodes("ds1", 1, split="test").n_steps == 1600  # 0.6 MB: under 1 MB


def test_cli_refuses_a_scenario_of_1e11_steps_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenarios = tmp_path / "huge.toml"
    scenarios.write_text('[scenario.huge]\nbase = "ds1"\nn_steps = 100_000_000_000\n')
    code = main(["run", "--scenario-file", str(scenarios), "--scenario", "huge", "--estimator", "manual-ekf",
                 "--seeds", "1", "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert err.startswith("fkn-bench run: error: a cell of 1 sequence(s) of 10000000000 steps (huge) would need about")
    assert MEMORY_LIMIT_VARIABLE in err and "--cut" in err
