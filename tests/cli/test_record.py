"""``fkn-bench record``: the file it writes, its summary text and JSON, and exit codes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fkn_bench.cli import main
from fkn_bench.envs import generate_episodes
from fkn_bench.envs.replay import load_episodes
from fkn_bench.recordings import list_topics, read_metadata
from fkn_bench.scenarios import registry


@pytest.fixture(autouse=True)
def isolated_registry(monkeypatch: pytest.MonkeyPatch) -> None:
    """--scenario-file registers scenarios: keep them out of other tests."""
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))


def test_record_writes_a_replayable_file(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "run.mcap"
    assert main(["record", "--scenario", "ds1", "--estimator", "manual-ekf", "--seed", "2", "--steps", "200",
                 "--out", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith(f"wrote {out}: 200 steps of ds1 (seed 2), ")
    assert "messages on 9 topics" in lines[0]
    assert any(line.split() == ["/fkn_bench/measured_pose", "20"] for line in lines[1:])
    topics = list_topics(out)
    assert topics["/loc/pose_with_covariance"].message_count == 200 - 0  # first measurement at step 0
    metadata = read_metadata(out)
    assert metadata["fkn_bench.estimator"]["name"] == "manual-ekf"
    assert metadata["fkn_bench.episode"]["seed"] == "2"
    replayed = load_episodes(out, seed=2)
    direct = generate_episodes("ds1", [2]).window(0, 200)
    # exact: lossless float64 MCAP round trip, measurements re-synthesised with the same seeded draws
    assert np.array_equal(replayed.truth, direct.truth)
    assert np.array_equal(replayed.measurements, direct.measurements, equal_nan=True)


def test_record_json_namespace_and_no_estimator(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "ns.mcap"
    assert main(["record", "--estimator", "none", "--steps", "50", "--namespace", "/bumble", "--no-foxglove",
                 "--compression", "lz4", "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["steps"] == 50 and summary["estimator"] is None
    assert set(summary["messages"]) == {"/bumble/loc/truth/pose", "/bumble/loc/truth/twist", "/bumble/fkn_bench/measured_pose"}
    assert {"size_bytes", "write_seconds", "estimate_seconds"} <= set(summary)


def test_record_scenario_file_and_split(tmp_path: Path) -> None:
    toml = tmp_path / "s.toml"
    toml.write_text('[scenario.mine]\nbase = "ds1"\nn_steps = 100\nmeasurement_every = 5\n')
    out = tmp_path / "mine.mcap"
    assert main(["record", "--scenario-file", str(toml), "--scenario", "mine", "--split", "test",
                 "--estimator", "none", "--out", str(out)]) == 0
    assert list_topics(out)["/loc/truth/pose"].message_count == 10
    assert read_metadata(out)["fkn_bench.episode"]["split"] == "test"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--estimator", "nope"], "unknown estimator 'nope'"),
        (["--scenario", "nope"], "unknown scenario 'nope'"),
        (["--seed", "-1"], "--seed must be a non-negative integer"),
        (["--steps", "0"], "--steps must be a positive integer"),
        (["--estimator", "missing.json"], "estimator file not found: missing.json"),
        (["--namespace", "a b"], "--namespace must not contain spaces"),
    ],
)
def test_usage_errors_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture, args: list[str], message: str) -> None:
    assert main(["record", "--out", str(tmp_path / "x.mcap"), *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("fkn-bench record: error: ") and message in err
    assert not (tmp_path / "x.mcap").exists()


def test_output_directory_is_a_usage_error(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["record", "--estimator", "none", "--steps", "10", "--out", str(tmp_path)]) == 2
    assert "is a directory" in capsys.readouterr().err


def test_out_is_required(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as info:
        main(["record"])
    assert info.value.code == 2
    assert "--out" in capsys.readouterr().err


def test_an_existing_out_file_is_replaced_only_with_force(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """Issue 34, finding 1: `fkn-bench record --out thesis.txt` replaced an existing file."""
    out = tmp_path / "thesis.txt"
    out.write_text("MINE\n")
    args = ["record", "--estimator", "none", "--steps", "10", "--out", str(out)]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err == f"fkn-bench record: error: --out {out} exists; choose another file name, or pass --force to replace it\n"
    assert out.read_text() == "MINE\n" and sorted(p.name for p in tmp_path.iterdir()) == ["thesis.txt"]
    leftover = tmp_path / ".thesis.txt.k1ll3d.tmp"  # what a record killed before its rename leaves
    leftover.write_bytes(b"half an MCAP")
    other = tmp_path / ".other.mcap.k1ll3d.tmp"  # another file's: not this command's to remove
    other.write_bytes(b"")
    assert main([*args, "--force"]) == 0
    assert list_topics(out)  # an MCAP now
    assert sorted(p.name for p in tmp_path.iterdir()) == [".other.mcap.k1ll3d.tmp", "thesis.txt"]
