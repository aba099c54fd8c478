"""Recording: every message read back with the mcap-ros2 decoder matches the in-memory episode;
Foxglove channels, metadata, compression, namespaces and the covariance mapping."""

from __future__ import annotations

import json
from collections import defaultdict

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from fkn_bench.recordings import (
    DEFAULT_START_EPOCH_NS,
    RecordingTopics,
    read_metadata,
    record_episode,
    ros_pose_covariance,
    write_recording,
)
from fkn_bench.scenarios import Scenario

TOPICS = RecordingTopics()


def _read_all(path) -> dict[str, list]:
    """topic -> [(schema, channel, message, decoded)] decoded by mcap-ros2-support (CDR) or JSON."""
    out: dict[str, list] = defaultdict(list)
    factory = DecoderFactory()
    with open(path, "rb") as fh:
        for schema, channel, message in make_reader(fh).iter_messages():
            if channel.message_encoding == "json":
                decoded = json.loads(message.data)
            else:
                decoded = factory.decoder_for(channel.message_encoding, schema)(message.data)
            out[channel.topic].append((schema, channel, message, decoded))
    return out


def _xyzw(q) -> np.ndarray:
    return np.array([q.x, q.y, q.z, q.w])


def _stamp(header) -> int:
    return header.stamp.sec * 10**9 + header.stamp.nanosec


def test_round_trip_every_message_bit_exact(recorded) -> None:
    episodes, estimates = recorded.episodes, recorded.estimates
    truth, meas, valid = episodes.truth[0], episodes.measurements[0], episodes.valid[0]
    stamps = DEFAULT_START_EPOCH_NS + np.round(episodes.times * 1e9).astype(np.int64)
    messages = _read_all(recorded.path)

    def check_header(entries, rows) -> None:
        assert len(entries) == len(rows)
        for (_, channel, message, decoded), k in zip(entries, rows):
            assert channel.message_encoding == "cdr"
            assert _stamp(decoded.header) == stamps[k] == message.log_time == message.publish_time
            assert decoded.header.frame_id == "world"

    every = np.arange(episodes.n_steps)
    entries = messages[TOPICS.truth_pose]
    check_header(entries, every)
    for (_, _, _, m), k in zip(entries, every):
        p = m.pose
        assert [p.position.x, p.position.y, p.position.z] == truth[k, 4:7].tolist()
        assert _xyzw(p.orientation).tolist() == [*truth[k, 1:4], truth[k, 0]]  # xyzw reorder only

    entries = messages[TOPICS.truth_twist]
    check_header(entries, every)
    for (_, _, _, m), k in zip(entries, every):
        assert [m.twist.angular.x, m.twist.angular.y, m.twist.angular.z] == truth[k, 7:10].tolist()
        assert [m.twist.linear.x, m.twist.linear.y, m.twist.linear.z] == truth[k, 10:13].tolist()

    measured = np.flatnonzero(valid)
    entries = messages[TOPICS.measured_pose]
    check_header(entries, measured)  # missing measurements are simply absent
    for (_, _, _, m), k in zip(entries, measured):
        assert [m.pose.position.x, m.pose.position.y, m.pose.position.z] == meas[k, 4:7].tolist()
        assert _xyzw(m.pose.orientation).tolist() == [*meas[k, 1:4], meas[k, 0]]

    rows = np.flatnonzero(estimates.initialised[0])
    assert rows[0] == measured[0]  # estimates start at the first measurement
    means, P = estimates.means[0], estimates.error_covariances[0]
    for topic in (TOPICS.estimated_pose, TOPICS.estimated_twist, TOPICS.estimated_pose_covariance):
        check_header(messages[topic], rows)
    for (_, _, _, m), k in zip(messages[TOPICS.estimated_pose], rows):
        assert [m.pose.position.x, m.pose.position.y, m.pose.position.z] == means[k, 4:7].tolist()
        assert _xyzw(m.pose.orientation).tolist() == [*means[k, 1:4], means[k, 0]]
    for (_, _, _, m), k in zip(messages[TOPICS.estimated_twist], rows):
        assert [m.twist.angular.x, m.twist.angular.y, m.twist.angular.z] == means[k, 7:10].tolist()
        assert [m.twist.linear.x, m.twist.linear.y, m.twist.linear.z] == means[k, 10:13].tolist()
    for (_, _, _, m), k in zip(messages[TOPICS.estimated_pose_covariance], rows):
        assert _xyzw(m.pose.pose.orientation).tolist() == [*means[k, 1:4], means[k, 0]]
        cov = np.array(m.pose.covariance).reshape(6, 6)  # exact below: float64 written and read back, reordered
        assert np.array_equal(cov[:3, :3], P[k, 3:6, 3:6])  # position block
        assert np.array_equal(cov[3:, 3:], P[k, 0:3, 0:3])  # attitude (rotation-vector) block
        assert np.array_equal(cov[:3, 3:], P[k, 3:6, 0:3])


def test_foxglove_channels(recorded) -> None:
    messages = _read_all(recorded.path)
    truth = recorded.episodes.truth[0]
    for topic in (TOPICS.foxglove_truth_pose, TOPICS.foxglove_measured_pose, TOPICS.foxglove_estimated_pose):
        schema, channel, _, _ = messages[topic][0]
        assert schema.name == "foxglove.PoseInFrame"
        assert schema.encoding == "jsonschema"
        assert channel.message_encoding == "json"
        assert json.loads(schema.data)["title"] == "foxglove.PoseInFrame"
    assert len(messages[TOPICS.foxglove_truth_pose]) == len(truth)
    assert len(messages[TOPICS.foxglove_measured_pose]) == int(recorded.episodes.valid.sum())
    for (_, _, message, doc), row in zip(messages[TOPICS.foxglove_truth_pose], truth):
        assert doc["frame_id"] == "world"
        assert doc["timestamp"]["sec"] * 10**9 + doc["timestamp"]["nsec"] == message.log_time
        o, p = doc["pose"]["orientation"], doc["pose"]["position"]
        assert [o["x"], o["y"], o["z"], o["w"]] == [*row[1:4], row[0]]
        assert [p["x"], p["y"], p["z"]] == row[4:7].tolist()


def test_file_layout_profile_schemas_and_compression(recorded) -> None:
    with open(recorded.path, "rb") as fh:
        reader = make_reader(fh)
        header = reader.get_header()
        summary = reader.get_summary()
    assert header.profile == "ros2"
    assert header.library.startswith("fkn-bench/")
    names = {s.name: s.encoding for s in summary.schemas.values()}
    assert names == {
        "geometry_msgs/msg/PoseStamped": "ros2msg",
        "geometry_msgs/msg/TwistStamped": "ros2msg",
        "geometry_msgs/msg/PoseWithCovarianceStamped": "ros2msg",
        "foxglove.PoseInFrame": "jsonschema",
    }
    assert len(summary.chunk_indexes) > 1
    assert {c.compression for c in summary.chunk_indexes} == {"zstd"}
    assert all(c.compressed_size < c.uncompressed_size for c in summary.chunk_indexes)
    counts = {summary.channels[cid].topic: n for cid, n in summary.statistics.channel_message_counts.items()}
    assert counts == recorded.summary.message_counts


def test_messages_are_in_time_order(recorded) -> None:
    with open(recorded.path, "rb") as fh:
        log_times = [m.log_time for _, _, m in make_reader(fh).iter_messages(log_time_order=False)]
    assert log_times == sorted(log_times)


def test_metadata(recorded) -> None:
    metadata = read_metadata(recorded.path)
    assert set(metadata) >= {
        "fkn_bench.recording",
        "fkn_bench.scenario",
        "fkn_bench.episode",
        "fkn_bench.estimator",
        "fkn_bench.provenance",
    }
    scenario = recorded.episodes.scenario
    stored = {k: json.loads(v) for k, v in metadata["fkn_bench.scenario"].items() if k != "config_hash"}
    assert Scenario.from_dict(stored) == scenario
    assert metadata["fkn_bench.scenario"]["config_hash"] == scenario.config_hash()
    assert metadata["fkn_bench.episode"]["seed"] == "3"
    assert metadata["fkn_bench.episode"]["split"] == "full"
    estimator = metadata["fkn_bench.estimator"]
    assert estimator["name"] == "manual-ekf"
    assert json.loads(estimator["config"]) == recorded.estimator.to_config()
    provenance = metadata["fkn_bench.provenance"]
    assert {"fkn_bench_version", "python", "numpy", "mcap", "created_utc", "command", "git_commit"} <= set(provenance)
    info = metadata["fkn_bench.recording"]
    assert info["format"] == "fkn-bench-recording"
    assert json.loads(info["topics"])["truth_pose"] == "/loc/truth/pose"
    assert int(info["start_epoch_ns"]) == DEFAULT_START_EPOCH_NS


@pytest.mark.parametrize("compression", ["lz4", "none"])
def test_other_compressions(tmp_path, short_episode, compression: str) -> None:
    episodes, estimates, _ = short_episode
    path = tmp_path / "c.mcap"
    record_episode(path, episodes, estimates, compression=compression, foxglove=False)
    with open(path, "rb") as fh:
        summary = make_reader(fh).get_summary()
    assert {c.compression for c in summary.chunk_indexes} == {"" if compression == "none" else "lz4"}
    assert not any(ch.topic.startswith("/foxglove") for ch in summary.channels.values())


def test_namespace_epoch_and_truth_only(tmp_path, short_episode) -> None:
    episodes, _, _ = short_episode
    path = tmp_path / "ns.mcap"
    summary = record_episode(path, episodes, None, namespace="honey", start_epoch_ns=10**18)
    assert set(summary.message_counts) == {
        "/honey/loc/truth/pose",
        "/honey/loc/truth/twist",
        "/honey/foxglove/truth_pose",
        "/honey/fkn_bench/measured_pose",
        "/honey/foxglove/measured_pose",
    }
    first = _read_all(path)["/honey/loc/truth/pose"][0]
    assert first[2].log_time == 10**18
    assert RecordingTopics.with_namespace("/honey/") == RecordingTopics.with_namespace("honey")
    with pytest.raises(ValueError, match="namespace"):
        RecordingTopics.with_namespace("a b")


def test_ros_pose_covariance_order() -> None:
    P = np.arange(144.0).reshape(12, 12)
    ros = ros_pose_covariance(P).reshape(6, 6)
    order = [3, 4, 5, 0, 1, 2]
    for i in range(6):
        for j in range(6):
            assert ros[i, j] == P[order[i], order[j]]
    assert ros_pose_covariance(np.stack([P, P])).shape == (2, 36)
    with pytest.raises(ValueError):
        ros_pose_covariance(np.eye(13))


def test_write_recording_input_checks(tmp_path) -> None:
    times = np.arange(5) * 0.1
    with pytest.raises(ValueError, match="strictly increasing"):
        write_recording(tmp_path / "a.mcap", times=times[::-1])
    with pytest.raises(ValueError, match=r"truth must have shape \(5, 13\)"):
        write_recording(tmp_path / "a.mcap", times=times, truth=np.zeros((5, 12)))
    with pytest.raises(ValueError, match="compression"):
        write_recording(tmp_path / "a.mcap", times=times, compression="brotli")
    assert not (tmp_path / "a.mcap").exists()


def test_chunking_and_compression_change_no_message(tmp_path, short_episode) -> None:
    """The same messages (topic, times, sequence, bytes) whatever the chunk size and compression;
    chunk CRCs validate and the statistics count every message."""
    episodes, estimates, _ = short_episode
    options = dict(
        times=episodes.times,
        truth=episodes.truth[0],
        measurements=episodes.measurements[0],
        valid=episodes.valid[0],
        estimates=estimates.means[0],
        estimate_error_covariances=estimates.error_covariances[0],
        estimate_mask=estimates.initialised[0],
        metadata={"fkn_bench.episode": {"seed": "3"}},
    )
    contents = []
    for compression, chunk_size in [("zstd", 1), ("lz4", 20_000), ("none", 4 << 20)]:
        path = tmp_path / f"{compression}.mcap"
        summary = write_recording(path, compression=compression, chunk_size=chunk_size, **options)
        with open(path, "rb") as fh:
            reader = make_reader(fh, validate_crcs=True)
            assert reader.get_summary().statistics.message_count == summary.message_count
            contents.append(
                [(c.topic, m.log_time, m.publish_time, m.sequence, m.data) for _, c, m in reader.iter_messages(log_time_order=False)]
            )
    assert contents[0] == contents[1] == contents[2]
