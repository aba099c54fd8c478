"""``fkn-bench run --recording ... --estimate-topic / --estimate``: other programs' estimates scored
beside fkn-bench's estimators (fkn_bench.envs.association, fkn_bench.estimators.external)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fkn_bench.cli import main
from fkn_bench.envs import Episodes, generate_episodes
from fkn_bench.estimators import make_estimator
from fkn_bench.geometry import quaternion as quat
from fkn_bench.recordings import DEFAULT_START_EPOCH_NS, record_episode
from fkn_bench.scenarios import get_scenario

SHORT = get_scenario("ds1", n_steps=300)
LATE = 15  # no measurement before this step: manual-ekf reports its prior there, and records nothing
NAMES = ("qw", "qx", "qy", "qz", "rx", "ry", "rz", "wx", "wy", "wz", "vx", "vy", "vz")
Q = quat.normalize(np.array([0.9, 0.1, -0.3, 0.2]))  # the estimate's world frame, seen from the truth's
T = np.array([0.5, -1.0, 2.0])


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Episodes]:
    """A ds1 recording whose estimate topics (/loc/pose, /loc/twist) hold manual-ekf's output."""
    episodes = generate_episodes(SHORT, [0])
    valid = episodes.valid.copy()
    valid[:, :LATE] = False
    episodes = Episodes(episodes.scenario, episodes.seeds, episodes.start, episodes.times, episodes.truth,
                        np.where(valid[..., None], episodes.measurements, np.nan), valid)
    estimates = make_estimator("manual-ekf", scenario=SHORT).estimate(episodes.measurements, episodes.valid, SHORT.dt)
    path = tmp_path_factory.mktemp("rec") / "short.mcap"
    record_episode(path, episodes, estimates=estimates)
    return path, episodes


def _run(capsys: pytest.CaptureFixture[str], *arguments: str) -> dict:
    assert main(["run", *arguments, "--json", "--no-progress"]) == 0
    return json.loads(capsys.readouterr().out)


def test_an_estimate_topic_of_our_own_output_scores_exactly_like_the_estimator(recording, capsys) -> None:
    path, episodes = recording
    document = _run(capsys, "--recording", str(path), "--measurement-topic", "/fkn_bench/measured_pose",
                    "--estimator", "manual-ekf", "--estimate-topic", "/loc/pose")
    ours, external = document["results"]
    assert (ours["estimator"], external["estimator"]) == ("manual-ekf", "external:/loc/pose")
    for name in NAMES:  # identical grids: association is exact, and the prior before the first estimate too
        assert external["rmse"][name] == pytest.approx(ours["rmse"][name], rel=1e-9, abs=1e-15)
    assert external["us_per_step"] is None and external["us_per_step_batched"] is None  # not fkn-bench's to time
    report = document["external"]["external:/loc/pose"]
    assert report["before_first_estimate"] == int(np.argmax(episodes.valid[0])) >= LATE and report["held"] == 0
    assert report["twist"] == "topic /loc/twist (world frame)"


def _truth_in_another_frame(episodes: Episodes, path: Path) -> Path:
    """The truth as a TUM file, in a world frame rotated by Q and shifted by T."""
    truth = episodes.truth[0]
    positions = (truth[:, 4:7] - T) @ quat.rotation_matrix(Q)  # R^T (p - T)
    attitudes = quat.wxyz_to_xyzw(quat.multiply(quat.conjugate(Q), truth[:, :4]))
    stamps = DEFAULT_START_EPOCH_NS + np.round(episodes.times * 1e9).astype(np.int64)
    lines = [f"{s // 10**9}.{s % 10**9:09d} " + " ".join(f"{v:.17g}" for v in (*p, *q))
             for s, p, q in zip(stamps, positions, attitudes)]
    path.write_text("# timestamp tx ty tz qx qy qz qw\n" + "\n".join(lines) + "\n")
    return path


def test_a_tum_file_in_another_frame_scores_zero_pose_error_after_se3_alignment(recording, tmp_path, capsys) -> None:
    path, episodes = recording
    tum = _truth_in_another_frame(episodes, tmp_path / "other-frame.tum")
    plain = _run(capsys, "--recording", str(path), "--estimator", "manual-ekf", "--seeds", "1", "--estimate", str(tum))
    assert plain["results"][1]["rmse"]["rx"] > 0.1  # unaligned: the frame offset
    document = _run(capsys, "--recording", str(path), "--estimator", "manual-ekf", "--seeds", "1",
                    "--estimate", str(tum), "--align", "se3")
    (external,) = [r for r in document["results"] if r["estimator"] == "external:other-frame.tum"]
    for name in NAMES[:7]:
        assert external["rmse"][name] < 1e-9, name
    alignment = document["external"]["external:other-frame.tum"]["alignment"]
    assert alignment["rotation_deg"] == pytest.approx(np.degrees(np.linalg.norm(quat.to_rotation_vector(Q))))
    np.testing.assert_allclose(alignment["translation_m"], T, atol=1e-9)
    assert "attitudes" in alignment["method"]  # ds1 tumbles in place: positions cannot fix the rotation


def test_external_estimate_usage_errors_exit_2(recording, tmp_path, capsys) -> None:
    path, _ = recording
    assert main(["run", "--estimate", "x.tum", "--no-progress"]) == 2
    assert "need --recording" in capsys.readouterr().err
    assert main(["run", "--recording", str(path), "--align", "se3", "--no-progress"]) == 2
    assert "need --estimate-topic or --estimate" in capsys.readouterr().err
    bad = tmp_path / "bad.tum"
    bad.write_text("1 0 0 0 0 0 0 1\n2 0 0 0 0 0 1\n")
    assert main(["run", "--recording", str(path), "--estimate", str(bad), "--no-progress"]) == 2
    assert capsys.readouterr().err.strip().splitlines()[-1] == (
        f"fkn-bench run: error: {bad}, line 2: 7 values; a TUM line has 8 (timestamp tx ty tz qx qy qz qw)")
    assert main(["run", "--recording", str(path), "--estimate-topic", "/nope", "--no-progress"]) == 2
    assert "/nope" in capsys.readouterr().err
