"""``fkn-bench bench report`` / ``gate`` (the speed suite's summary and the speed gate's CLI)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fkn_bench.cli import main
from fkn_bench.cli.bench import summarize_benchmarks

DOCUMENT = {
    "machine_info": {"machine": "x86_64", "python_implementation": "CPython", "python_version": "3.11.7",
                     "cpu": {"brand_raw": "Test CPU", "count": 2}},
    "commit_info": {"id": "0123456789abcdef", "dirty": True},
    "datetime": "2026-01-01T00:00:00",
    "version": "5.3.1",
    "benchmarks": [
        {"name": "test_filter_forward[ekf]", "group": None, "extra_info": {"steps": 12800, "what": "ekf run()"},
         "stats": {"min": 0.09, "max": 0.2, "mean": 0.11, "stddev": 0.011, "rounds": 5, "median": 0.1}},
        {"name": "test_ekf_forward_batch_1024", "group": None, "extra_info": {"steps": 204800, "batch": 1024},
         "stats": {"min": 0.2, "max": 0.3, "mean": 0.25, "stddev": 0.01, "rounds": 3, "median": 0.256}},
        {"name": "test_small_bmm_limit[1024]", "group": None,
         "extra_info": {"steps": 512, "batch": 1024, "small_bmm_limit": True},
         "stats": {"min": 2e-4, "max": 3e-4, "mean": 2.6e-4, "stddev": 1e-5, "rounds": 7, "median": 2.56e-4}},
        {"name": "test_without_steps", "group": None, "extra_info": {},
         "stats": {"min": 2e-6, "max": 3e-6, "mean": 2.5e-6, "stddev": 1e-7, "rounds": 100, "median": 2.5e-6}},
    ],
}


def test_summary_rows_have_throughputs() -> None:
    rows = summarize_benchmarks(DOCUMENT)
    assert rows[0]["steps_per_s"] == pytest.approx(128000.0)
    assert rows[-1]["steps"] is None and rows[-1]["steps_per_s"] is None


def test_batched_rows_report_their_fraction_of_the_small_bmm_limit_at_their_batch() -> None:
    rows = {row["name"]: row for row in summarize_benchmarks(DOCUMENT)}
    limit = rows["test_small_bmm_limit[1024]"]
    assert limit["steps_per_s"] == pytest.approx(2e6) and limit["of_bmm_limit"] is None
    assert rows["test_ekf_forward_batch_1024"]["of_bmm_limit"] == pytest.approx(800e3 / 2e6)
    assert rows["test_filter_forward[ekf]"]["of_bmm_limit"] is None  # no batch, no limit


def test_report_prints_a_table_with_steps_per_second(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    path = tmp_path / "bench.json"
    path.write_text(json.dumps(DOCUMENT))
    assert main(["bench", "report", str(path)]) == 0
    out = capsys.readouterr().out
    assert "Test CPU, 2 CPUs, CPython 3.11.7; commit 0123456789ab (dirty)" in out
    line = next(l for l in out.splitlines() if l.startswith("test_filter_forward[ekf]"))
    assert "100 ms" in line and "110 ms" in line and "12800" in line and "128 k" in line and "10%" in line
    line = next(l for l in out.splitlines() if l.startswith("test_ekf_forward_batch_1024"))
    assert "800 k" in line and "0.40" in line
    assert main(["bench", "report", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["benchmarks"][0]["steps_per_s"] == pytest.approx(128000.0)


def test_report_errors(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["bench", "report", str(tmp_path / "missing.json")]) == 2
    assert "not found" in capsys.readouterr().err
    (tmp_path / "other.json").write_text('{"results": []}')
    assert main(["bench", "report", str(tmp_path / "other.json")]) == 2
    assert "--benchmark-json" in capsys.readouterr().err


def test_gate_lists_checks_and_rejects_unknown_ones(capsys: pytest.CaptureFixture) -> None:
    assert main(["bench", "gate", "--list"]) == 0
    out = capsys.readouterr().out
    assert "ekf-forward" in out and "train-epoch" in out and "online-step:manual-ekf" in out
    assert main(["bench", "gate", "--check", "nonsense"]) == 2
    assert "valid checks" in capsys.readouterr().err


def test_gate_measures_one_check(capsys: pytest.CaptureFixture) -> None:
    """A real measurement, reported as JSON, its verdict that of its last attempt. Whether it
    passes depends on the machine's load (the other test worker's too), so the verdict is the
    test command's next step (``fkn-bench bench gate --trips``), not asserted here; the exit
    status follows it."""
    code = main(["bench", "gate", "--check", "online-step:manual-ekf", "--json"])
    (outcome,) = json.loads(capsys.readouterr().out)
    assert outcome["check"] == "online-step:manual-ekf" and 1 <= len(outcome["attempts"]) <= 3
    ratios = [attempt["ratio"] for attempt in outcome["attempts"]]
    assert all(ratio > 0 for ratio in ratios) and all(ratio < outcome["min_ratio"] for ratio in ratios[:-1])
    assert outcome["passed"] == (ratios[-1] >= outcome["min_ratio"]) and code == (0 if outcome["passed"] else 1)


def test_bench_compile_readies_every_kernel(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    """``fkn-bench bench compile`` (the test command's first step) compiles, or loads from numba's
    cache, all four EKF kernels; with the kernels off it says so, exit 2."""
    from fkn_bench.cli import main
    from fkn_bench.filters import kernels

    assert main(["bench", "compile"]) == 0
    assert "4 kernels ready (predict_forward, predict_backward, update_forward, update_backward)" in capsys.readouterr().err
    monkeypatch.setattr(kernels, "ENABLED", False)
    assert main(["bench", "compile"]) == 2
    assert "the compiled kernels are off here" in capsys.readouterr().err
