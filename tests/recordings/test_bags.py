"""ROS 1 and ROS 2 bags, written with rosbags' own writers, read through open_recording: Astrobee's
topic layout replayed with the truth as written (and scored by ``fkn-bench run``), ROS 2 sqlite3
and mcap storage, a truncated bag, missing topics, and pose covariances in fkn-bench's order."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin, Writer as Writer2
from rosbags.typesys import Stores, get_typestore

from fkn_bench.cli import main
from fkn_bench.envs.replay import load_episodes, read_recording
from fkn_bench.estimators import make_estimator
from fkn_bench.geometry import quaternion as quat
from fkn_bench.metrics import MetricSettings, score_run
from fkn_bench.recordings import (
    BagRecording,
    McapRecording,
    RecordingError,
    TopicNotFoundError,
    open_recording,
)

TRUTH, TWIST, MEASURED = "/loc/truth/pose", "/loc/truth/twist", "/loc/measured/pose"
N, DT = 40, 0.1  # ds1's step: the replay grid lands on every message
EPOCH_NS = 1_735_689_600 * 1_000_000_000
STAMPS = EPOCH_NS + np.round(np.arange(N) * DT * 1e9).astype(np.int64)
BAD_COVARIANCES = (3, 7)  # message 3: all zero (ROS's "unknown"), 7: not symmetric


def _ros_covariance() -> np.ndarray:
    """A 6x6 ROS pose covariance (x, y, z, rot x, rot y, rot z) with an x / rot-z cross term."""
    c = np.diag([1e-4, 2e-4, 3e-4, 1e-5, 2e-5, 3e-5])
    c[0, 5] = c[5, 0] = 1e-6
    return c


@pytest.fixture(scope="module")
def written(tools) -> tuple[np.ndarray, np.ndarray]:
    """Truth states (N, 13) of a constant world-frame rotation, and measured poses (N, 7)."""
    _, states = tools.forced_rotation(N, DT)
    noise = np.random.default_rng(2).normal(0.0, 1e-3, (N, 6))
    measured = np.concatenate(
        [quat.multiply(quat.from_rotation_vector(noise[:, :3]), states[:, :4]), states[:, 4:7] + noise[:, 3:]], axis=1
    )
    return states, measured


def _messages(ros1: bool, states: np.ndarray, measured: np.ndarray) -> dict[str, tuple[str, list[object]]]:
    """topic -> (type, messages) built from the typestore's classes."""
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    t = store.types
    msg = {name.split("/")[-1]: t[name] for name in (
        "builtin_interfaces/msg/Time", "std_msgs/msg/Header", "geometry_msgs/msg/Point", "geometry_msgs/msg/Quaternion",
        "geometry_msgs/msg/Pose", "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/Vector3", "geometry_msgs/msg/Twist",
        "geometry_msgs/msg/TwistStamped", "geometry_msgs/msg/PoseWithCovariance",
        "geometry_msgs/msg/PoseWithCovarianceStamped",
    )}

    def header(k: int) -> object:
        stamp = msg["Time"](sec=int(STAMPS[k]) // 10**9, nanosec=int(STAMPS[k]) % 10**9)
        return msg["Header"](seq=k, stamp=stamp, frame_id="world") if ros1 else msg["Header"](stamp=stamp, frame_id="world")

    def pose(row: np.ndarray) -> object:
        x, y, z, w = quat.wxyz_to_xyzw(row[:4])
        return msg["Pose"](position=msg["Point"](*row[4:7]), orientation=msg["Quaternion"](x=x, y=y, z=z, w=w))

    covariances = np.repeat(_ros_covariance()[None], N, axis=0)
    covariances[BAD_COVARIANCES[0]] = 0.0
    covariances[BAD_COVARIANCES[1], 0, 1] += 1e-6
    return {
        TRUTH: ("geometry_msgs/msg/PoseStamped", [msg["PoseStamped"](header(k), pose(states[k])) for k in range(N)]),
        TWIST: ("geometry_msgs/msg/TwistStamped", [
            msg["TwistStamped"](header(k), msg["Twist"](msg["Vector3"](*states[k, 10:13]), msg["Vector3"](*states[k, 7:10])))
            for k in range(N)
        ]),
        MEASURED: ("geometry_msgs/msg/PoseWithCovarianceStamped", [
            msg["PoseWithCovarianceStamped"](header(k), msg["PoseWithCovariance"](pose(measured[k]), covariances[k].ravel()))
            for k in range(N)
        ]),
    }


def _write(path: Path, ros1: bool, states: np.ndarray, measured: np.ndarray, storage: str = "sqlite3") -> Path:
    """A bag of Astrobee's topic layout, messages logged 1 ms after their stamps."""
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    serialize = store.serialize_ros1 if ros1 else store.serialize_cdr
    if ros1:
        writer = Writer1(path)
    else:
        plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP
        writer = Writer2(path, version=9, storage_plugin=plugin)
    with writer:
        for topic, (msgtype, messages) in _messages(ros1, states, measured).items():
            connection = writer.add_connection(topic, msgtype, typestore=store)
            for k, message in enumerate(messages):
                writer.write(connection, int(STAMPS[k]) + 1_000_000, serialize(message, msgtype))
    return path


@pytest.fixture(scope="module")
def ros1_bag(tmp_path_factory: pytest.TempPathFactory, written) -> Path:
    return _write(tmp_path_factory.mktemp("bags") / "astrobee.bag", True, *written)


def _check_replay(path: Path, states: np.ndarray, measured: np.ndarray) -> None:
    trajectory = read_recording(path, measurement_topic=MEASURED)
    episodes = trajectory.episodes(0)
    assert np.array_equal(episodes.truth[0], states)  # bit for bit: float64 through the bag and back
    assert np.array_equal(episodes.measurements[0], measured) and episodes.valid.all()
    report = trajectory.report
    assert (report.truth_topic, report.twist_source, report.twist_frame) == (TRUTH, f"topic {TWIST}", "world")
    assert report.interpolated_steps == 0 and report.repairs == ()


def test_a_ros1_bag_with_astrobee_topics_replays_the_truth_as_written(ros1_bag, written) -> None:
    recording = open_recording(ros1_bag)
    assert isinstance(recording, BagRecording) and recording.kind == "ROS 1 bag"
    topics = recording.topics()
    assert {t: (i.type_name, i.message_encoding, i.message_count) for t, i in topics.items()} == {
        TRUTH: ("geometry_msgs/PoseStamped", "ros1", N),
        TWIST: ("geometry_msgs/TwistStamped", "ros1", N),
        MEASURED: ("geometry_msgs/PoseWithCovarianceStamped", "ros1", N),
    }
    assert recording.metadata() == {}
    _check_replay(ros1_bag, *written)  # the truth topic found by Astrobee's name, the twist beside it


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_ros2_bags_replay_the_truth_as_written(tmp_path, written, storage: str) -> None:
    bag = _write(tmp_path / f"bag_{storage}", False, *written, storage=storage)
    assert isinstance(open_recording(bag), BagRecording)
    assert open_recording(bag / "metadata.yaml").path == bag
    assert open_recording(bag).topics()[TRUTH].message_encoding == "cdr"
    _check_replay(bag, *written)
    (storage_file,) = bag.glob("*.db3" if storage == "sqlite3" else "*.mcap")  # the storage file alone
    alone = open_recording(storage_file)
    assert isinstance(alone, BagRecording if storage == "sqlite3" else McapRecording)
    assert np.array_equal(alone.read_poses(TRUTH).poses, written[0][:, :7])


def test_fkn_bench_run_scores_a_ros1_bag(ros1_bag, written, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["run", "--recording", str(ros1_bag), "--measurement-topic", MEASURED, "--estimator", "manual-ekf",
                 "--cut", "5", "--json", "--no-progress"])
    assert code == 0
    (result,) = json.loads(capsys.readouterr().out)["results"]
    episodes = load_episodes(ros1_bag, measurement_topic=MEASURED)
    direct = make_estimator("manual-ekf", scenario=episodes.scenario).estimate(
        episodes.measurements, episodes.valid, DT
    )
    scores = score_run(written[0][None], direct.means, DT, settings=MetricSettings(cut=5))
    assert result["rmse"]["qw"] == pytest.approx(float(scores.component_rmse[0, 0]), rel=1e-9, abs=1e-15)
    assert result["rmse"]["rx"] == pytest.approx(float(scores.component_rmse[0, 4]), rel=1e-9, abs=1e-15)


def test_pose_covariances_come_back_in_fkn_bench_order(ros1_bag) -> None:
    recording = open_recording(ros1_bag)
    series = recording.read_poses(MEASURED)
    assert series.covariances.shape == (N, 6, 6)
    c = _ros_covariance()
    expected = np.block([[c[3:, 3:], c[3:, :3]], [c[:3, 3:], c[:3, :3]]])  # [dtheta, dr] from (r, rot)
    assert expected[2, 3] == 1e-6  # the x / rot-z cross term: (dtheta_z, dr_x)
    good = np.setdiff1d(np.arange(N), BAD_COVARIANCES)
    assert np.array_equal(series.covariances[good], np.repeat(expected[None], len(good), axis=0))
    assert np.isnan(series.covariances[list(BAD_COVARIANCES)]).all()
    assert series.notes == (
        f"{MEASURED}: 2 of {N} pose covariance(s) are not finite, symmetric and positive definite (first: #3); "
        "kept as NaN",
    )
    assert recording.read_poses(TRUTH).covariances is None


def test_a_truncated_bag_is_a_one_line_error(tmp_path, ros1_bag) -> None:
    data = ros1_bag.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: len(data) // 2])
    for repair in (False, True):
        with pytest.raises(RecordingError, match=r"cut.bag: rosbags cannot read this ROS 1 bag: \w+") as info:
            load_episodes(cut, repair=repair)
        assert "\n" not in str(info.value) and info.value.path == cut
    with pytest.raises(RecordingError, match=r"ROS 1 bag \(.bag\), not MCAP; open it with fkn_bench.recordings.open_recording"):
        McapRecording(ros1_bag)


def test_missing_empty_and_unknown(tmp_path, ros1_bag) -> None:
    with pytest.raises(RecordingError, match="recording not found: .*nope.bag"):
        open_recording(tmp_path / "nope.bag")
    (tmp_path / "empty.bag").write_bytes(b"")
    with pytest.raises(RecordingError, match=r"empty.bag: the file is empty \(0 bytes\); it is not an MCAP"):
        open_recording(tmp_path / "empty.bag")
    (tmp_path / "dir").mkdir()
    with pytest.raises(RecordingError, match="directory without metadata.yaml"):
        open_recording(tmp_path / "dir")
    with pytest.raises(TopicNotFoundError, match=r"truth topic '/nope' not found; topics in this recording:\n.*/loc/truth/pose"):
        load_episodes(ros1_bag, truth_topic="/nope")


def test_a_recorded_measurement_covariance_becomes_that_steps_r(ros1_bag, capsys: pytest.CaptureFixture[str]) -> None:
    """The replayed episode carries the covariances on the measurements' steps, and
    ``--estimator-option measurement_noise=message`` filters with them (the two messages without a
    usable one take the default R, which the run's notes count)."""
    episodes = load_episodes(ros1_bag, measurement_topic=MEASURED)
    covariances = episodes.measurement_covariances[0]
    stated = np.isfinite(covariances).all(axis=(1, 2))
    assert stated.sum() == episodes.valid.sum() - len(BAD_COVARIANCES)
    assert np.array_equal(covariances[stated][0], open_recording(ros1_bag).read_poses(MEASURED).covariances[0])
    told = make_estimator("manual-mekf", scenario=episodes.scenario, measurement_noise="message")
    estimates = told.estimate(episodes.measurements, episodes.valid, DT,
                              measurement_covariances=episodes.measurement_covariances)
    assert estimates.extras["measurement_noise_defaults"].tolist() == [len(BAD_COVARIANCES)]
    assert np.isfinite(estimates.means).all()
    code = main(["run", "--recording", str(ros1_bag), "--measurement-topic", MEASURED, "--estimator", "manual-mekf",
                 "--estimator-option", "measurement_noise=message", "--cut", "5", "--no-progress"])
    assert code == 0
    assert f"{len(BAD_COVARIANCES)} measured step(s) stated no usable covariance" in capsys.readouterr().err
