"""Message serialisation: CDR written by mcap-ros2-support and read back by rosbags (our
decode_stamped) and by mcap-ros2-support, ROS 1 bytes as the ROS 1 wire format defines them, Foxglove JSON, decoding errors, and the
schema texts."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
from mcap_ros2._dynamic import generate_dynamic

from fkn_bench.recordings.codecs import (
    LAYOUTS,
    DecodeError,
    decode_pose_in_frame,
    decode_stamped,
    encode_pose_in_frame,
    encode_ros2,
)
from fkn_bench.recordings.schemas import FOXGLOVE_SCHEMAS, ROS2_DEFINITIONS, ros2_schema_text

STAMPS = np.array([0, 1_735_689_600_123_456_789, 5_000_000_001])


@pytest.mark.parametrize("name", sorted(ROS2_DEFINITIONS))
def test_cdr_round_trip_through_mcap_ros2(name: str) -> None:
    """Every alignment case: frame ids of 0..9 characters (and child frames for Odometry); the
    library's bytes decode to the same message with its decoder and ours."""
    decoder = generate_dynamic(name, ROS2_DEFINITIONS[name])[name]
    n = LAYOUTS[name.replace("/msg/", "/")].n_doubles
    rng = np.random.default_rng(0)
    children = range(0, 10, 3) if "Odometry" in name else [0]
    for frame_len in range(10):
        for child_len in children:
            frame, child = "abcdefghij"[:frame_len], "XYZWVUTSRQ"[:child_len]
            values = rng.standard_normal((3, n))
            encoded = encode_ros2(name, STAMPS, values, frame, child_frame_id=child)
            for i, stamp in enumerate(STAMPS.tolist()):
                decoded = decoder(encoded[i])
                assert decoded.header.frame_id == frame
                assert decoded.header.stamp.sec * 10**9 + decoded.header.stamp.nanosec == stamp
                got = decode_stamped(name, "cdr", encoded[i])
                assert got[0] == stamp and got[1] == frame
                assert got[2] == (child if "Odometry" in name else "")
                assert np.array_equal(got[3], values[i, : len(got[3])])  # exact: float64 bytes round trip
                assert len(got[3]) == (49 if "Odometry" in name else n)  # Odometry's twist covariance is not read
                if "Odometry" in name:
                    assert decoded.child_frame_id == child
                    assert list(decoded.twist.covariance) == values[i, 49:85].tolist()


@pytest.mark.parametrize("name", sorted(LAYOUTS))
def test_ros1_wire_format_is_read(name: str, tools) -> None:
    layout = LAYOUTS[name]
    values = np.random.default_rng(1).standard_normal((3, layout.n_doubles))
    child = "body" if layout.child_frame else None
    for i, stamp in enumerate(STAMPS.tolist()):
        got = decode_stamped(name, "ros1", tools.ros1_message(7 + i, stamp, "world", child, values[i].tolist()))
        assert got[0] == stamp and got[1] == "world" and got[2] == (child or "")
        assert np.array_equal(got[3], values[i, : len(got[3])])  # exact: float64 bytes round trip


def test_both_spellings_of_a_type_name_work() -> None:
    values = np.ones((1, 7))
    a = encode_ros2("geometry_msgs/msg/PoseStamped", STAMPS[:1], values, "w")
    b = encode_ros2("geometry_msgs/PoseStamped", STAMPS[:1], values, "w")
    assert a == b


def test_stamps_out_of_range_are_refused() -> None:
    with pytest.raises(ValueError, match="time stamps must lie in"):
        encode_ros2("geometry_msgs/PoseStamped", np.array([-1]), np.ones((1, 7)), "w")
    with pytest.raises(ValueError, match="time stamps must lie in"):
        encode_pose_in_frame(np.array([2**31 * 10**9]), "w", np.ones((1, 7)))
    with pytest.raises(ValueError, match="shape"):
        encode_ros2("geometry_msgs/PoseStamped", STAMPS, np.ones((3, 6)), "w")


def test_decode_errors_name_the_problem() -> None:
    good = encode_ros2("geometry_msgs/PoseStamped", STAMPS[:1], np.ones((1, 7)), "world")[0]
    """rosbags' own accounts of what it could not read, one line each."""
    with pytest.raises(DecodeError, match="Could not deserialize 'geometry_msgs/msg/PoseStamped': unpack_from requires"):
        decode_stamped("geometry_msgs/PoseStamped", "cdr", good[:-3])
    with pytest.raises(DecodeError, match="Invalid or unsupported CDR encapsulation"):
        decode_stamped("geometry_msgs/PoseStamped", "cdr", b"\x00\x07\x00\x00" + good[4:])
    with pytest.raises(DecodeError, match="Could not deserialize"):
        decode_stamped("geometry_msgs/PoseStamped", "cdr", good[:6])
    bad_length = good[:12] + struct.pack("<I", 10_000) + good[16:]
    with pytest.raises(DecodeError, match="Invalid string length 10000"):
        decode_stamped("geometry_msgs/PoseStamped", "cdr", bad_length)
    no_nul = good[:21] + b"x" + good[22:]
    with pytest.raises(DecodeError, match="Missing string terminator"):
        decode_stamped("geometry_msgs/PoseStamped", "cdr", no_nul)
    with pytest.raises(DecodeError, match="Could not deserialize"):
        decode_stamped("geometry_msgs/PoseStamped", "ros1", good[:10])
    with pytest.raises(DecodeError, match="unknown message encoding 'protobuf'"):
        decode_stamped("geometry_msgs/PoseStamped", "protobuf", good)


def test_big_endian_cdr_is_read() -> None:
    body = struct.pack(">iI", 12, 34) + struct.pack(">I", 6) + b"world\x00" + b"\x00" * 6
    body += struct.pack(">7d", *range(7))
    stamp, frame, _, values = decode_stamped("geometry_msgs/PoseStamped", "cdr", b"\x00\x00\x00\x00" + body)
    assert (stamp, frame, values) == (12 * 10**9 + 34, "world", tuple(float(v) for v in range(7)))


def test_foxglove_json_round_trip_is_exact() -> None:
    values = np.random.default_rng(2).standard_normal((5, 7))
    stamps = STAMPS[1] + np.arange(5) * 100_000_000
    for stamp, raw, row in zip(stamps.tolist(), encode_pose_in_frame(stamps, "world", values), values):
        document = json.loads(raw)
        assert document["frame_id"] == "world"
        assert document["timestamp"] == {"sec": stamp // 10**9, "nsec": stamp % 10**9}
        got_stamp, frame, got = decode_pose_in_frame(raw)
        assert got_stamp == stamp and frame == "world" and np.array_equal(got, row)  # exact: JSON float repr round trip
        assert decode_stamped("foxglove.PoseInFrame", "json", raw) == (got_stamp, frame, "", got)


def test_foxglove_json_non_finite_becomes_null_and_decodes_to_nan() -> None:
    values = np.array([[1.0, np.nan, 3.0, 0.0, 0.0, 0.0, 1.0]])
    raw = encode_pose_in_frame(STAMPS[:1], "world", values)[0]
    assert json.loads(raw)["pose"]["position"]["y"] is None
    assert np.isnan(decode_pose_in_frame(raw)[2][1])


@pytest.mark.parametrize(
    ("raw", "match"),
    [
        (b"{not json", "not valid JSON"),
        (b'{"timestamp": {"sec": 1, "nsec": 2}}', "missing or malformed field"),
        (b'{"timestamp": {"sec": -1, "nsec": 2}, "pose": {"position": {"x": 0, "y": 0, "z": 0}, '
         b'"orientation": {"x": 0, "y": 0, "z": 0, "w": 1}}}', "non-negative"),
        (b'{"timestamp": {"sec": 1, "nsec": 2}, "pose": {"position": {"x": "a", "y": 0, "z": 0}, '
         b'"orientation": {"x": 0, "y": 0, "z": 0, "w": 1}}}', "must be a number"),
    ],
)
def test_foxglove_json_errors(raw: bytes, match: str) -> None:
    with pytest.raises(DecodeError, match=match):
        decode_pose_in_frame(raw)


def test_ros2_schema_texts_have_the_rosbag2_layout() -> None:
    text = ros2_schema_text("geometry_msgs/PoseStamped")
    assert text.startswith("std_msgs/Header header\nPose pose\n")
    sections = text.split("=" * 80 + "\n")
    assert [s.splitlines()[0] for s in sections[1:]] == [
        "MSG: std_msgs/Header",
        "MSG: builtin_interfaces/Time",
        "MSG: geometry_msgs/Pose",
        "MSG: geometry_msgs/Point",
        "MSG: geometry_msgs/Quaternion",
    ]
    schema = json.loads(FOXGLOVE_SCHEMAS["foxglove.PoseInFrame"])
    assert schema["title"] == "foxglove.PoseInFrame"
    assert schema["required"] == ["timestamp", "frame_id", "pose"]
