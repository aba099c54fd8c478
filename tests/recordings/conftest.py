"""Fixtures for the recording tests: a short recorded episode, and builders of small MCAP files."""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.writer import CompressionType, Writer

from fkn_bench.envs import Episodes, generate_episodes
from fkn_bench.estimators import Estimates, make_estimator
from fkn_bench.geometry import quaternion as quat
from fkn_bench.recordings.codecs import encode_pose_in_frame, encode_ros2
from fkn_bench.recordings.schemas import FOXGLOVE_SCHEMAS, SEPARATOR, ros2_schema_text
from fkn_bench.scenarios import get_scenario

SHORT_STEPS = 300
EPOCH_NS = 1_735_689_600 * 1_000_000_000


@dataclass
class RecordedEpisode:
    """A short ds1 episode with manual-ekf estimates, recorded to ``path``."""

    path: Path
    episodes: Episodes
    estimates: Estimates
    estimator: Any
    summary: Any


@pytest.fixture(scope="session")
def short_episode() -> tuple[Episodes, Estimates, Any]:
    scenario = get_scenario("ds1").replace(n_steps=SHORT_STEPS)
    episodes = generate_episodes(scenario, [3])
    estimator = make_estimator("manual-ekf", scenario=scenario)
    estimates = estimator.estimate(episodes.measurements, episodes.valid, scenario.dt)
    return episodes, estimates, estimator


@pytest.fixture(scope="session")
def recorded(tmp_path_factory: pytest.TempPathFactory, short_episode) -> RecordedEpisode:
    from fkn_bench.recordings import record_episode

    episodes, estimates, estimator = short_episode
    path = tmp_path_factory.mktemp("recorded") / "episode.mcap"
    summary = record_episode(path, episodes, estimates, estimator=estimator, chunk_size=16 * 1024)
    return RecordedEpisode(path, episodes, estimates, estimator, summary)


# ---------------------------------------------------------------------------- custom files
@dataclass
class ChannelSpec:
    """One channel of a hand-made MCAP file: its schema and ``(log_time, data)`` messages."""

    topic: str
    schema_name: str
    schema_encoding: str
    schema_data: bytes
    message_encoding: str
    messages: list[tuple[int, bytes]] = field(default_factory=list)


def write_mcap(
    path: Path,
    channels: Sequence[ChannelSpec],
    *,
    profile: str = "ros2",
    chunk_size: int = 1024 * 1024,
    compression: CompressionType = CompressionType.ZSTD,
    metadata: dict[str, dict[str, str]] | None = None,
) -> Path:
    """Write ``channels`` with the mcap Writer, messages interleaved by log time."""
    with open(path, "wb") as fh:
        writer = Writer(fh, chunk_size=chunk_size, compression=compression)
        writer.start(profile=profile, library="fkn-bench tests")
        for name, record in (metadata or {}).items():
            writer.add_metadata(name, record)
        ids = []
        for spec in channels:
            schema_id = writer.register_schema(spec.schema_name, spec.schema_encoding, spec.schema_data)
            ids.append(writer.register_channel(spec.topic, spec.message_encoding, schema_id))
        queue = sorted(
            ((log, n, i, data) for i, spec in enumerate(channels) for n, (log, data) in enumerate(spec.messages)),
            key=lambda item: (item[0], item[2], item[1]),
        )
        for log, n, i, data in queue:
            writer.add_message(ids[i], log_time=log, data=data, publish_time=log, sequence=n)
        writer.finish()
    return path


def pose_values(poses: np.ndarray) -> np.ndarray:
    """ROS pose fields (position, quaternion xyzw) of ``[q wxyz, r]`` rows."""
    return np.concatenate([poses[:, 4:7], quat.wxyz_to_xyzw(poses[:, :4])], axis=1)


def pose_channel(
    topic: str,
    stamps_ns: np.ndarray,
    poses: np.ndarray,
    *,
    encoding: str = "cdr",
    type_name: str = "geometry_msgs/PoseStamped",
    frame_id: str = "world",
    log_ns: np.ndarray | None = None,
    extra: np.ndarray | None = None,
    child_frame_id: str = "",
) -> ChannelSpec:
    """A pose channel: ``poses (N, 7)`` = ``[q wxyz, r]``; ``extra`` appends further float64
    fields (covariance, Odometry twist) in ROS order."""
    stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
    log_ns = stamps_ns if log_ns is None else np.asarray(log_ns, dtype=np.int64)
    values = pose_values(np.asarray(poses, dtype=float))
    if type_name == "foxglove.PoseInFrame":
        data = encode_pose_in_frame(stamps_ns, frame_id, values)
        return ChannelSpec(topic, type_name, "jsonschema", FOXGLOVE_SCHEMAS[type_name], "json", list(zip(log_ns.tolist(), data)))
    if extra is not None:
        values = np.concatenate([values, extra], axis=1)
    return _ros_channel(topic, type_name, encoding, stamps_ns, log_ns, values, frame_id, child_frame_id)


def twist_channel(
    topic: str,
    stamps_ns: np.ndarray,
    angular: np.ndarray,
    linear: np.ndarray,
    *,
    encoding: str = "cdr",
    frame_id: str = "world",
    log_ns: np.ndarray | None = None,
) -> ChannelSpec:
    stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
    log_ns = stamps_ns if log_ns is None else np.asarray(log_ns, dtype=np.int64)
    values = np.concatenate([np.asarray(linear, float), np.asarray(angular, float)], axis=1)
    return _ros_channel(topic, "geometry_msgs/TwistStamped", encoding, stamps_ns, log_ns, values, frame_id, "")


def ros1_schema_text(name: str) -> str:
    """The ``ros1msg`` definition of ``name`` (fkn-bench writes only ROS 2): the ROS 2 one with
    ROS 1's ``std_msgs/Header`` (``uint32 seq``, builtin ``time``) and no ``builtin_interfaces``."""
    sections = ros2_schema_text(name).split(SEPARATOR + "\n")
    text = (SEPARATOR + "\n").join(s for s in sections if not s.startswith("MSG: builtin_interfaces/Time"))
    return text.replace("builtin_interfaces/Time stamp\n", "uint32 seq\ntime stamp\n")


def ros1_message(seq: int, stamp: int, frame: str, child: str | None, values: Sequence[float]) -> bytes:
    """ROS 1 wire format written field by field (fkn-bench reads ROS 1 but writes only ROS 2):
    uint32 seq, time (uint32 secs, nsecs), string (uint32 length + bytes), then float64 fields,
    little-endian and unaligned; ``child`` is Odometry's child_frame_id (None for other types)."""
    sec, nsec = divmod(stamp, 10**9)
    out = struct.pack("<III", seq, sec, nsec) + struct.pack("<I", len(frame)) + frame.encode()
    if child is not None:
        out += struct.pack("<I", len(child)) + child.encode()
    return out + struct.pack(f"<{len(values)}d", *values)


def _ros_channel(topic, type_name, encoding, stamps_ns, log_ns, values, frame_id, child) -> ChannelSpec:
    package, _, name = type_name.replace("/msg/", "/").partition("/")
    if encoding == "cdr":
        schema_name, schema_encoding, text = f"{package}/msg/{name}", "ros2msg", ros2_schema_text(type_name)
        data = encode_ros2(type_name, stamps_ns, values, frame_id, child_frame_id=child)
    else:
        schema_name, schema_encoding, text = f"{package}/{name}", "ros1msg", ros1_schema_text(type_name)
        odometry = name == "Odometry"
        data = [ros1_message(i, s, frame_id, child if odometry else None, v)
                for i, (s, v) in enumerate(zip(stamps_ns.tolist(), np.asarray(values, float).tolist()))]
    return ChannelSpec(topic, schema_name, schema_encoding, text.encode(), encoding, list(zip(log_ns.tolist(), data)))


def forced_rotation(n: int, dt: float, *, omega=(0.1, 0.2, 0.3), q0=None, r0=(1.0, 2.0, 3.0), v=(0.01, -0.02, 0.03)):
    """Exact states of a constant world-frame rotation and constant velocity at ``k * dt``."""
    t = np.arange(n) * dt
    omega = np.asarray(omega, dtype=float)
    q0 = quat.normalize(np.array([0.9, 0.1, -0.3, 0.2])) if q0 is None else np.asarray(q0, dtype=float)
    q = quat.multiply(quat.from_rotation_vector(t[:, None] * omega), q0)
    r = np.asarray(r0) + t[:, None] * np.asarray(v)
    states = np.concatenate([q, r, np.tile(omega, (n, 1)), np.tile(np.asarray(v, float), (n, 1))], axis=1)
    return t, states


@pytest.fixture
def make_mcap(tmp_path: Path) -> Callable[..., Path]:
    """``make_mcap(name, channels, **write_mcap options)`` -> path in ``tmp_path``."""

    def make(name: str, channels: Sequence[ChannelSpec], **options: Any) -> Path:
        return write_mcap(tmp_path / name, channels, **options)

    return make


@pytest.fixture
def simple_truth(make_mcap) -> Callable[..., Path]:
    """A file with a 40-step ``/loc/truth/pose`` (PoseStamped, CDR) at 10 Hz; options change the
    stamps or poses before writing: ``simple_truth(name, stamps=..., poses=...)``."""

    def make(name: str = "truth.mcap", *, stamps=None, poses=None, log=None, **options: Any) -> Path:
        t, states = forced_rotation(40, 0.1)
        stamps = EPOCH_NS + np.round(t * 1e9).astype(np.int64) if stamps is None else np.asarray(stamps)
        poses = states[:, :7] if poses is None else np.asarray(poses)
        return make_mcap(name, [pose_channel("/loc/truth/pose", stamps, poses, log_ns=log)], **options)

    return make


@pytest.fixture(scope="session")
def tools() -> Any:
    """The helpers of this conftest (test modules cannot import it under importlib mode)."""
    from types import SimpleNamespace

    return SimpleNamespace(
        ChannelSpec=ChannelSpec,
        write_mcap=write_mcap,
        pose_channel=pose_channel,
        twist_channel=twist_channel,
        ros1_message=ros1_message,
        ros1_schema_text=ros1_schema_text,
        pose_values=pose_values,
        forced_rotation=forced_rotation,
        EPOCH_NS=EPOCH_NS,
        SHORT_STEPS=SHORT_STEPS,
    )
