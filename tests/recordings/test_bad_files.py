"""Bad files: each case gives a RecordingError naming the file, the topic and the message, or,
with ``repair=True``, the documented repair reported to the user. Files are made here."""

from __future__ import annotations

import struct
import warnings

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType

from fkn_bench.envs.replay import read_recording
from fkn_bench.recordings import (
    McapRecording,
    RecordingError,
    RecordingRepairWarning,
    TopicNotFoundError,
    record_episode,
)


def _replay(path, **options):
    """read_recording, returning (trajectory, its reported repairs); checks that each repair was
    also issued as a RecordingRepairWarning naming the file."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        trajectory = read_recording(path, dt="native", **options)
    issued = [str(w.message) for w in caught if issubclass(w.category, RecordingRepairWarning)]
    repairs = list(trajectory.report.repairs)
    assert issued == [f"{path}: {r}" for r in repairs]
    return trajectory, repairs


def _error(path, match: str, **options) -> RecordingError:
    with pytest.raises(RecordingError, match=match) as info:
        read_recording(path, dt="native", **options)
    assert str(path) in str(info.value)
    return info.value


@pytest.fixture
def multi_chunk(tmp_path, short_episode):
    """A 300-step recording in many small chunks."""
    episodes, estimates, _ = short_episode
    path = tmp_path / "chunks.mcap"
    record_episode(path, episodes, None, chunk_size=4096, foxglove=False)
    with open(path, "rb") as fh:
        summary = make_reader(fh).get_summary()
    return path, sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset), episodes


# ---------------------------------------------------------------------------- not a recording
def test_missing_file(tmp_path) -> None:
    with pytest.raises(RecordingError, match="recording not found: .*nope.mcap"):
        read_recording(tmp_path / "nope.mcap")


def test_empty_file(tmp_path) -> None:
    path = tmp_path / "empty.mcap"
    path.write_bytes(b"")
    _error(path, r"the file is empty \(0 bytes\)")


@pytest.mark.parametrize(
    ("content", "match"),
    [
        (b"#ROSBAG V2.0\n" + bytes(100), r"a ROS 1 bag; rosbags reads it only under a name ending in .bag"),
        (b"SQLite format 3\x00" + bytes(100), r"a ROS 2 sqlite3 bag; rosbags reads it only under a name ending in .db3"),
        (bytes(range(64)), "not an MCAP file"),
        (b"\x89MCAP", r"truncated: 5 bytes"),
    ],
)
def test_not_mcap(tmp_path, content: bytes, match: str) -> None:
    path = tmp_path / "bad.mcap"
    path.write_bytes(content)
    _error(path, match)


def test_mcap_without_topics_or_messages(make_mcap, tools) -> None:
    empty = make_mcap("nothing.mcap", [])
    error = _error(empty, "none named <robot>/loc/truth/pose")
    assert "the recording has no topics" in str(error)
    spec = tools.pose_channel("/loc/truth/pose", np.array([], dtype=np.int64), np.zeros((0, 7)))
    silent = make_mcap("silent.mcap", [spec])
    _error(silent, "truth topic '/loc/truth/pose' has no messages", truth_topic="/loc/truth/pose")


# ---------------------------------------------------------------------------- damaged files
def test_truncated_file(multi_chunk) -> None:
    path, chunks, episodes = multi_chunk
    data = path.read_bytes()
    cut = path.with_name("cut.mcap")
    cut.write_bytes(data[: chunks[len(chunks) // 2].chunk_start_offset + 100])  # cut inside a chunk
    error = _error(cut, "truncated or was not closed properly.*repair=True.*mcap recover")
    assert error.path == cut
    trajectory, repairs = _replay(cut, repair=True)
    assert any("read the file front to back" in r for r in repairs)
    assert any("stopped reading at record" in r for r in repairs)
    n = trajectory.n_steps
    assert 2 < n < episodes.n_steps
    # exact here and below: MCAP stores float64 losslessly
    assert np.array_equal(trajectory.truth, episodes.truth[0, :n])  # what was read is intact


def test_corrupt_chunk(multi_chunk) -> None:
    path, chunks, episodes = multi_chunk
    data = bytearray(path.read_bytes())
    victim = chunks[3]
    middle = victim.chunk_start_offset + victim.chunk_length // 2
    data[middle : middle + 8] = bytes(b ^ 0xFF for b in data[middle : middle + 8])
    bad = path.with_name("corrupt.mcap")
    bad.write_bytes(bytes(data))
    _error(bad, rf"chunk 3 \(bytes {victim.chunk_start_offset}-\d+\) is corrupt.*repair=True")
    trajectory, repairs = _replay(bad, repair=True)
    assert any(r.startswith("skipped chunk 3 (bytes") and "which is corrupt" in r for r in repairs)
    start = round((victim.message_start_time - chunks[0].message_start_time) / 1e8)
    assert np.array_equal(trajectory.truth[:start], episodes.truth[0, :start])
    assert any("gaps of up to" in note for note in trajectory.report.notes)


def test_corrupt_summary(multi_chunk) -> None:
    path, _, episodes = multi_chunk
    data = bytearray(path.read_bytes())
    # footer: opcode, length, summary_start u64, summary_offset_start u64, crc u32, then magic
    footer = len(data) - 8 - (1 + 8 + 8 + 8 + 4)
    data[footer + 9 : footer + 17] = struct.pack("<Q", len(data) - 12)
    bad = path.with_name("summary.mcap")
    bad.write_bytes(bytes(data))
    _error(bad, "summary section cannot be read")
    trajectory, repairs = _replay(bad, repair=True)
    assert repairs and np.array_equal(trajectory.truth, episodes.truth[0])


# ---------------------------------------------------------------------------- unsupported content
def test_unknown_message_encoding(make_mcap, tools) -> None:
    spec = tools.ChannelSpec("/loc/truth/pose", "foxglove.PoseInFrame", "protobuf", b"\x00", "protobuf", [(1, b"\x01")])
    path = make_mcap("proto.mcap", [spec])
    _error(path, "topic '/loc/truth/pose' uses message encoding 'protobuf'.*reads 'cdr'")


def test_unknown_message_type(make_mcap, tools) -> None:
    spec = tools.ChannelSpec("/imu", "sensor_msgs/msg/Imu", "ros2msg", b"float64 x\n", "cdr", [(1, b"\x00\x01\x00\x00")])
    path = make_mcap("imu.mcap", [spec])
    _error(path, "truth topic '/imu' has type 'sensor_msgs/msg/Imu'.*must be one of", truth_topic="/imu")


def test_unknown_chunk_compression(simple_truth) -> None:
    path = simple_truth("lz4.mcap", compression=CompressionType.LZ4)
    data = path.read_bytes()
    assert b"\x03\x00\x00\x00lz4" in data
    path.write_bytes(data.replace(b"\x03\x00\x00\x00lz4", b"\x03\x00\x00\x00br9"))
    _error(path, r"chunk 0 \(bytes \d+-\d+\) is corrupt: it uses chunk compression 'br9'")


# ---------------------------------------------------------------------------- bad messages
def _truth(tools, n=40):
    t, states = tools.forced_rotation(n, 0.1)
    return tools.EPOCH_NS + np.round(t * 1e9).astype(np.int64), states


def test_non_monotonic_timestamps(simple_truth, tools) -> None:
    stamps, states = _truth(tools)
    log = stamps.copy()
    log[[5, 6]] = log[[6, 5]]  # message 6 is logged before message 5
    path = simple_truth(stamps=stamps, log=log)
    error = _error(path, r"truth topic '/loc/truth/pose': message #6 has stamp .* earlier than message #5.*not monotonic.*sort")
    assert (error.topic, error.index) == ("/loc/truth/pose", 6)
    trajectory, repairs = _replay(path, repair=True)
    assert repairs == ["/loc/truth/pose: sorted the messages by stamp (1 went backwards; first: #6)"]
    assert np.array_equal(trajectory.truth[:, :7], states[:, :7])
    assert trajectory.report.repairs == tuple(repairs)


def test_duplicate_timestamps(simple_truth, tools) -> None:
    stamps, states = _truth(tools)
    header = stamps.copy()
    header[8] = header[7]
    path = simple_truth(stamps=header, log=stamps)
    _error(path, r"message #8 has the same stamp .* as message #7 \(duplicate time stamps\).*keep only the first")
    trajectory, repairs = _replay(path, repair=True, twist_topic=None)
    assert repairs == ["/loc/truth/pose: dropped 1 message(s) with a duplicate stamp, keeping the first of each (first dropped: #8)"]
    assert trajectory.report.truth_messages == 39
    assert np.array_equal(trajectory.truth[7, :7], states[7, :7])


def test_non_unit_quaternion(simple_truth, tools) -> None:
    stamps, states = _truth(tools)
    poses = states[:, :7].copy()
    poses[3, :4] *= 1.2
    path = simple_truth(poses=poses)
    error = _error(path, r"message #3 has a quaternion of norm 1\.2, not 1 \(tolerance 1e-06\).*renormalise")
    assert error.index == 3
    trajectory, repairs = _replay(path, repair=True)
    assert repairs == ["/loc/truth/pose: renormalised 1 quaternion(s) with a norm off 1 by more than 1e-06 (first: #3, norm 1.2)"]
    assert np.allclose(trajectory.truth[3, :4], states[3, :4], atol=1e-15)
    relaxed, repairs = _replay(path, quaternion_tolerance=0.5)
    assert repairs == [] and relaxed.truth[3, 0] == poses[3, 0]


@pytest.mark.parametrize(
    ("row", "value", "match"),
    [(4, ("q", 0.0), "a zero quaternion"), (9, ("r", np.nan), r"a non-finite value \(NaN or infinity\)"),
     # issue 34: a truth position of 1e300 was accepted and its overflow scored as the estimator diverging
     (7, ("r", 1e300), r"an implausible value \(rx = 1e\+300 m is beyond \+-1e\+06 m\)")],
)
def test_zero_quaternions_and_non_finite_values(simple_truth, tools, row, value, match) -> None:
    stamps, states = _truth(tools)
    poses = states[:, :7].copy()
    poses[row, slice(0, 4) if value[0] == "q" else slice(4, 7)] = value[1]
    path = simple_truth(poses=poses)
    _error(path, rf"message #{row} has {match}.*drop")
    trajectory, repairs = _replay(path, repair=True)
    assert len(repairs) == 1 and "dropped 1 message(s)" in repairs[0]
    assert trajectory.report.truth_messages == 39


def test_an_implausible_resampled_truth_is_a_named_error(simple_truth, tools) -> None:
    """Issue 34: plausible poses 2 ns apart give a finite-difference angular rate of 1e7 rad/s;
    the replayed truth is refused, naming the file, topic and step, instead of being scored."""
    stamps, states = _truth(tools)
    stamps[19], stamps[21] = stamps[20] - 1, stamps[20] + 1  # message 20 stays on grid step 20
    path = simple_truth(stamps=stamps)  # (messages 19 and 21, 0.2 s of rotation apart, now 2 ns apart)
    error = _error(path, r"the true state of step 20 .*truth '/loc/truth/pose', twist from finite differences\) is "
                         r"implausible: wx = 1e\+07 rad/s is beyond \+-1000 rad/s", twist_topic=None)
    assert error.topic == "/loc/truth/pose"


def test_zero_stamp_among_others(simple_truth, tools) -> None:
    stamps, _ = _truth(tools)
    header = stamps.copy()
    header[12] = 0
    path = simple_truth(stamps=header, log=stamps)
    _error(path, "message #12 has a zero header stamp while others do not")
    _, repairs = _replay(path, repair=True)
    assert repairs == ["/loc/truth/pose: dropped 1 message(s) with a zero header stamp (first: #12)"]
    log_based, repairs = _replay(path, time_source="log")
    assert repairs == [] and log_based.report.time_source == "log"


def test_undecodable_message(make_mcap, tools) -> None:
    stamps, states = _truth(tools)
    spec = tools.pose_channel("/loc/truth/pose", stamps, states[:, :7])
    log, data = spec.messages[2]
    spec.messages[2] = (log, data[:30])
    path = make_mcap("short.mcap", [spec])
    _error(path, r"message #2 \(log time .*\) cannot be decoded as geometry_msgs/msg/PoseStamped \(ROS 2 CDR\): Could not deserialize")
    trajectory, repairs = _replay(path, repair=True)
    assert repairs == ["/loc/truth/pose: dropped 1 undecodable message(s) (first: #2)"]


def test_errors_are_value_errors_with_context(simple_truth, tools) -> None:
    stamps, states = _truth(tools)
    poses = states[:, :7].copy()
    poses[3, :4] *= 2
    path = simple_truth(poses=poses)
    with pytest.raises(ValueError) as info:
        McapRecording(path).read_poses("/loc/truth/pose")
    assert isinstance(info.value, RecordingError)
    assert (info.value.path, info.value.topic, info.value.index) == (path, "/loc/truth/pose", 3)
    with pytest.raises(TopicNotFoundError):
        McapRecording(path).read_poses("/other")


def test_a_stamp_gap_that_would_resample_to_more_than_memory_is_refused_first(make_mcap, tools, monkeypatch) -> None:
    """300 poses with one 1e6 s stamp gap at dt 0.1 s would be 1e7 steps (about 75 GiB with the
    estimators' covariances): refused before anything is allocated, naming the file, the span,
    the limit and how to raise it."""
    from fkn_bench.limits import MEMORY_LIMIT_VARIABLE, SizeLimitError

    stamps, states = _truth(tools, n=300)
    stamps = stamps.copy()
    stamps[150:] += 10**15  # 1e6 s
    path = make_mcap("gap.mcap", [tools.pose_channel("/loc/truth/pose", stamps, states[:, :7])])
    monkeypatch.setenv(MEMORY_LIMIT_VARIABLE, "4")
    with pytest.raises(SizeLimitError, match=rf"replaying {path}: its truth spans 1.00003e\+06 s, 1.00003e\+07 steps of 0.1 s would need about 74.5 GiB of memory, over the limit of 4 GiB \({MEMORY_LIMIT_VARIABLE}\); ask for a larger time step \(--dt SECONDS\)"):
        read_recording(path, dt=0.1)


def test_the_command_line_names_its_flags_and_prints_repairs_in_one_line_each(simple_truth, tools, capsys) -> None:
    """Issue 18: the refusal that a Python caller reads as "Pass repair=True" reads "Pass
    --repair" on the command line, and with ``--repair`` each repair is one line of the
    recording's summary (no Python warning with its source line)."""
    from fkn_bench.cli import main

    stamps, _ = _truth(tools)
    header = stamps.copy()
    header[8] = header[7]
    path = str(simple_truth(stamps=header, log=stamps))
    _error(path, r"Pass repair=True to keep only the first")  # the Python spelling, outside the command line
    command = ["run", "--recording", path, "--estimator", "manual-ekf", "--seeds", "1", "--no-progress", "--dt", "native",
               "--cut", "5"]
    assert main(command) == 2
    err = capsys.readouterr().err
    assert "Pass --repair to keep only the first message of each stamp" in err and "repair=True" not in err
    assert len(err.strip().splitlines()) == 1
    assert main([*command, "--repair"]) == 0
    err = capsys.readouterr().err
    assert "  repair: /loc/truth/pose: dropped 1 message(s) with a duplicate stamp" in err
    assert "Warning" not in err and "warnings.warn" not in err and ".py:" not in err
