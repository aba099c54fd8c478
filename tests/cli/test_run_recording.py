"""``fkn-bench run --recording``: estimators scored on an MCAP recording."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fkn_bench.cli import main
from fkn_bench.envs import generate_episodes
from fkn_bench.estimators import make_estimator
from fkn_bench.metrics import score_run
from fkn_bench.recordings import record_episode
from fkn_bench.scenarios import get_scenario

SHORT = get_scenario("ds1", n_steps=1200)


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, object]:
    episodes = generate_episodes(SHORT, [0])
    path = tmp_path_factory.mktemp("rec") / "short.mcap"
    record_episode(path, episodes)
    return path, episodes


def test_recorded_measurements_score_like_the_direct_run(recording, capsys: pytest.CaptureFixture[str]) -> None:
    path, episodes = recording
    code = main(["run", "--recording", str(path), "--measurement-topic", "/fkn_bench/measured_pose",
                 "--estimator", "manual-ekf", "--json", "--no-progress"])
    assert code == 0
    document = json.loads(capsys.readouterr().out)
    (result,) = document["results"]
    assert result["seeds"] == [0]
    direct = make_estimator("manual-ekf", scenario=SHORT).estimate(episodes.measurements, episodes.valid, SHORT.dt)
    scores = score_run(episodes.truth, direct.means, SHORT.dt)
    for index, name in enumerate(("qw", "qx", "qy", "qz", "rx", "ry", "rz", "wx", "wy", "wz", "vx", "vy", "vz")):
        assert result["rmse"][name] == pytest.approx(float(scores.component_rmse[0, index]), rel=1e-9, abs=1e-15)


def test_recording_usage_errors_exit_2(recording, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path, _ = recording
    assert main(["run", "--recording", str(tmp_path / "missing.mcap"), "--no-progress"]) == 2
    assert "not found" in capsys.readouterr().err
    assert main(["run", "--recording", str(path), "--scenario", "ds1", "--no-progress"]) == 2
    assert "replaces --scenario" in capsys.readouterr().err
    assert main(["run", "--recording", str(path), "--dt", "fast", "--no-progress"]) == 2
    assert "--dt" in capsys.readouterr().err
    assert main(["run", "--recording", str(path), "--truth-topic", "/nope", "--no-progress"]) == 2
    assert "/nope" in capsys.readouterr().err


def test_an_implausible_recorded_truth_is_exit_2_not_a_divergence(recording, tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 34, finding 2: a truth position of 1e300 in an MCAP file was accepted, and its
    overflow reported as the estimator diverging."""
    _, episodes = recording
    truth = episodes.truth.copy()
    truth[0, 700, 4] = 1e300
    path = tmp_path / "implausible.mcap"
    record_episode(path, type(episodes)(episodes.scenario, episodes.seeds, episodes.start, episodes.times, truth,
                                        episodes.measurements, episodes.valid))
    assert main(["run", "--recording", str(path), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(path) in err
    assert "message #700 has an implausible value (rx = 1e+300 m is beyond +-1e+06 m)" in err
