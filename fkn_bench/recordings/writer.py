"""Write episodes as MCAP recordings that ROS 2 tools and Foxglove open.

One file holds one episode (:func:`write_recording` for arrays, :func:`record_episode` for an
:class:`~fkn_bench.envs.Episodes` row and its :class:`~fkn_bench.estimators.Estimates`;
:func:`fkn_bench.exporters.recording.record` generates an episode, runs an estimator and records both).

Topics (:class:`RecordingTopics`; a ``namespace`` such as ``/honey`` is prepended to each), all
with ``header.frame_id = "world"``:

* ``/loc/truth/pose`` (``geometry_msgs/msg/PoseStamped``, cdr): the true pose, every step;
* ``/loc/truth/twist`` (``geometry_msgs/msg/TwistStamped``, cdr): the true twist, every step;
* ``/fkn_bench/measured_pose`` (``geometry_msgs/msg/PoseStamped``, cdr): the measured pose at
  the steps that have one (missing measurements are simply absent);
* ``/loc/pose`` (``PoseStamped``) and ``/loc/twist`` (``TwistStamped``): the estimate;
* ``/loc/pose_with_covariance`` (``geometry_msgs/msg/PoseWithCovarianceStamped``): the
  estimated pose with its 6x6 covariance (when the estimator gives error covariances);
* ``/foxglove/truth_pose``, ``/foxglove/measured_pose``, ``/foxglove/estimated_pose``
  (``foxglove.PoseInFrame``, json, schema encoding ``jsonschema``): the same poses for
  Foxglove's 3-D panel (display frame "world").

The truth and estimate topics use Astrobee's names (``loc/truth/pose``, ``loc/truth/twist``,
``loc/pose``, ``loc/twist``; nasa/astrobee ``ff_util/ff_names.h``), so the
replay reader and Astrobee tooling find them. Estimates are written from the step at which the
estimator initialised (its first usable measurement) on; a ROS node publishes nothing before.

Conventions at this edge (the rest of fkn-bench is scalar-first, see :mod:`fkn_bench.types`):

* Quaternions are written ``x, y, z, w`` (ROS and Foxglove order), body to world, unchanged
  otherwise (bit-exact, including their sign).
* Every message has ``header.frame_id = "world"`` (``frame_id``). Twists are **world-frame**:
  ``linear`` is the velocity and ``angular`` the angular velocity, both expressed in "world" (as
  Astrobee's Gazebo truth plugin publishes ``loc/truth/twist``), not in the body frame.
* ``PoseWithCovarianceStamped.pose.covariance`` is the row-major 6x6 covariance of
  ``(x, y, z, rot_x, rot_y, rot_z)``: the position block and the attitude block of the estimator's
  12-dim error covariance ``[dtheta, dr, dw, dv]`` reordered position first. The rotation part is
  the covariance of the world-frame rotation-vector error ``dtheta`` with
  ``q_true = exp(dtheta/2) (x) q_est`` (small rotations about the fixed "world" axes). ROS
  documents these three parameters as rotations about the fixed X, Y and Z axes; for the small
  errors a covariance describes the two agree to first order (small fixed-axis rotations commute
  to first order and compose to the rotation vector).
* Time: step ``k`` of an episode with times ``t_k`` (s) is stamped
  ``start_epoch_ns + round(t_k * 1e9)`` ns (``header.stamp.sec`` / ``nanosec``), and that stamp is
  also the message's MCAP ``log_time`` and ``publish_time``. The default epoch,
  :data:`DEFAULT_START_EPOCH_NS`, is 2025-01-01T00:00:00Z (ROS treats a zero stamp as "unset").

Metadata records (all values strings): ``fkn_bench.recording`` (format, conventions, topics as
JSON), ``fkn_bench.scenario`` (each scenario field JSON-encoded, plus ``config_hash``),
``fkn_bench.episode`` (seed, split, first step, steps), ``fkn_bench.estimator`` (name, class,
JSON config) and ``fkn_bench.provenance`` (versions, platform, command line, git commit, time).

Chunks are zstd-compressed by default (``compression``). The CDR bytes are serialised by
``mcap-ros2-support`` and the file written by ``mcap``'s ``Writer``.
"""

from __future__ import annotations

import datetime as _dt
import json
import sys
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

import numpy as np
from mcap.writer import LIBRARY_IDENTIFIER as MCAP_LIBRARY
from mcap.writer import CompressionType, Writer

from fkn_bench import __version__
from fkn_bench.geometry.quaternion import wxyz_to_xyzw
from fkn_bench.io import atomic_path, to_jsonable
from fkn_bench.provenance import environment
from fkn_bench.recordings.codecs import encode_pose_in_frame, encode_ros2
from fkn_bench.recordings.schemas import FOXGLOVE_SCHEMAS, ros2_schema_text
from fkn_bench.types import ArrayB, ArrayF

__all__ = [
    "DEFAULT_START_EPOCH_NS", "RECORDING_FORMAT", "RECORDING_FORMAT_VERSION", "COMPRESSIONS",
    "RecordingTopics", "RecordingSummary", "ros_pose_covariance", "write_recording",
    "record_episode", "provenance", "episode_metadata"
]

DEFAULT_START_EPOCH_NS = 1_735_689_600 * 1_000_000_000
"""Stamp of ``t = 0``: 2025-01-01T00:00:00Z, in ns since the Unix epoch."""

RECORDING_FORMAT = "fkn-bench-recording"
RECORDING_FORMAT_VERSION = 1

COMPRESSIONS: dict[str, CompressionType] = {name: CompressionType[name.upper()] for name in ("zstd", "lz4", "none")}

_POSE = "geometry_msgs/msg/PoseStamped"
_TWIST = "geometry_msgs/msg/TwistStamped"
_POSE_COV = "geometry_msgs/msg/PoseWithCovarianceStamped"
_FOXGLOVE_POSE = "foxglove.PoseInFrame"

# position-first order of the ROS 6x6 pose covariance, as indices into [dtheta, dr, ...]
_ROS_POSE_ORDER = np.array([3, 4, 5, 0, 1, 2])


@dataclass(frozen=True)
class RecordingTopics:
    """Topic names of a recording (see the module docstring for types and contents)."""

    truth_pose: str = "/loc/truth/pose"
    truth_twist: str = "/loc/truth/twist"
    measured_pose: str = "/fkn_bench/measured_pose"
    estimated_pose: str = "/loc/pose"
    estimated_twist: str = "/loc/twist"
    estimated_pose_covariance: str = "/loc/pose_with_covariance"
    foxglove_truth_pose: str = "/foxglove/truth_pose"
    foxglove_measured_pose: str = "/foxglove/measured_pose"
    foxglove_estimated_pose: str = "/foxglove/estimated_pose"

    @classmethod
    def with_namespace(cls, namespace: str = "") -> RecordingTopics:
        """The default names under ``namespace`` (``"honey"`` -> ``/honey/loc/truth/pose``)."""
        if not isinstance(namespace, str) or any(c.isspace() for c in namespace):
            raise ValueError(f"namespace must be a string without spaces (got {namespace!r})")
        prefix = "/" + namespace.strip("/") if namespace.strip("/") else ""
        return cls(**{f.name: prefix + f.default for f in fields(cls)})  # type: ignore[operator]


@dataclass(frozen=True)
class RecordingSummary:
    """What :func:`write_recording` wrote.

    Attributes:
        path: the file.
        n_steps: episode steps.
        message_counts: messages per topic (topics without messages are not written).
        size_bytes: file size.
        write_seconds: wall time of encoding and writing.
        topics: the topic names used.
        timings: extra wall times (:func:`fkn_bench.exporters.recording.record` adds
            ``generate_seconds``, ``estimate_seconds``).
    """

    path: Path
    n_steps: int
    message_counts: dict[str, int]
    size_bytes: int
    write_seconds: float
    topics: RecordingTopics
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def message_count(self) -> int:
        return sum(self.message_counts.values())


def ros_pose_covariance(error_covariance: ArrayF) -> ArrayF:
    """ROS ``PoseWithCovariance.covariance`` rows ``(..., 36)`` from 12x12 error covariances
    ``(..., 12, 12)`` ordered ``[dtheta, dr, dw, dv]`` (see module docstring)."""
    P = np.asarray(error_covariance, dtype=np.float64)
    if P.shape[-2:] != (12, 12):
        raise ValueError(f"error covariances must have shape (..., 12, 12) (got {P.shape})")
    block = P[..., _ROS_POSE_ORDER, :][..., :, _ROS_POSE_ORDER]  # same order for rows and columns: symmetric as P is
    return block.reshape(*P.shape[:-2], 36)


def provenance() -> dict[str, str]:
    """The ``fkn_bench.provenance`` metadata (MCAP metadata values are strings): the versions,
    machine and git commit of :func:`fkn_bench.provenance.environment`, the mcap packages'
    versions, the command line and the time."""

    def package_version(name: str) -> str:
        try:
            return version(name)
        except PackageNotFoundError:
            return ""

    env = environment()
    return {
        "fkn_bench_version": str(env["fkn_bench"]),
        "python": str(env["python"]),
        "platform": str(env["machine"]["platform"]),
        "numpy": str(env["numpy"]),
        "mcap": package_version("mcap"),
        "mcap_ros2_support": package_version("mcap-ros2-support"),
        "command": json.dumps(sys.argv),
        "git_commit": env["git_commit"] or "",
        "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }


def _checked(name: str, array: Any, shape: tuple[int, ...], dtype: type = np.float64) -> Any:
    """``array`` as ``dtype``, checked to have ``shape``; None stays None."""
    if array is None:
        return None
    out = np.asarray(array)
    if out.shape != shape:
        raise ValueError(f"{name} must have shape {shape} (got {out.shape})")
    return out.astype(dtype, copy=False)


def _pose_values(states: ArrayF) -> ArrayF:
    """ROS pose fields ``(N, 7)`` = position, quaternion xyzw of states/measurements [q, r, ...]."""
    return np.concatenate([states[:, 4:7], wxyz_to_xyzw(states[:, 0:4])], axis=1)


def _twist_values(states: ArrayF) -> ArrayF:
    """ROS twist fields ``(N, 6)`` = linear (v), angular (w) of 13-dim states."""
    return np.concatenate([states[:, 10:13], states[:, 7:10]], axis=1)


def write_recording(
    path: str | Path,
    *,
    times: ArrayF,
    truth: ArrayF | None = None,
    measurements: ArrayF | None = None,
    valid: ArrayB | None = None,
    estimates: ArrayF | None = None,
    estimate_error_covariances: ArrayF | None = None,
    estimate_mask: ArrayB | None = None,
    metadata: Mapping[str, Mapping[str, str]] | None = None,
    topics: RecordingTopics | None = None,
    namespace: str = "",
    frame_id: str = "world",
    start_epoch_ns: int = DEFAULT_START_EPOCH_NS,
    foxglove: bool = True,
    compression: str = "zstd",
    chunk_size: int = 4 * 1024 * 1024,
) -> RecordingSummary:
    """Write one episode's arrays to an MCAP file (atomically).

    Args:
        path: output file (``.mcap``).
        times: ``(T,)`` strictly increasing sample times, s.
        truth: ``(T, 13)`` true states, or None.
        measurements: ``(T, 7)`` measured poses ``[q wxyz, r]``; only rows where ``valid`` are
            written (all rows when ``valid`` is None, NaN rows skipped).
        valid: ``(T,)`` measurement validity.
        estimates: ``(T, 13)`` state estimates, written where ``estimate_mask`` (default: all).
        estimate_error_covariances: ``(T, 12, 12)`` error covariances ``[dtheta, dr, dw, dv]``
            for ``PoseWithCovarianceStamped`` (topic skipped when None).
        metadata: extra metadata records ``{name: {key: value}}`` (strings).
        topics: topic names (default :class:`RecordingTopics` under ``namespace``).
        frame_id: ``header.frame_id`` of every message.
        start_epoch_ns: stamp of ``t = 0``, ns.
        foxglove: also write the ``foxglove.PoseInFrame`` channels.
        compression: chunk compression, ``"zstd"`` (default), ``"lz4"`` or ``"none"``.
        chunk_size: uncompressed bytes per chunk.
    """
    started = time.perf_counter()
    times = np.asarray(times, dtype=np.float64)
    if times.ndim != 1 or len(times) == 0:
        raise ValueError(f"times must be a non-empty 1-d array (got shape {times.shape})")
    if not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
        raise ValueError("times must be finite and strictly increasing")
    n = len(times)
    truth = _checked("truth", truth, (n, 13))
    measurements = _checked("measurements", measurements, (n, 7))
    valid = _checked("valid", valid, (n,), bool)
    estimates = _checked("estimates", estimates, (n, 13))
    covariances = _checked("estimate_error_covariances", estimate_error_covariances, (n, 12, 12))
    estimate_mask = _checked("estimate_mask", estimate_mask, (n,), bool)
    if compression not in COMPRESSIONS:
        raise ValueError(f"compression must be one of {', '.join(COMPRESSIONS)} (got {compression!r})")
    topics = topics if topics is not None else RecordingTopics.with_namespace(namespace)
    stamps = int(start_epoch_ns) + np.round(times * 1e9).astype(np.int64)  # see the module docstring
    if np.any(np.diff(stamps) <= 0):
        raise ValueError("times closer than 1 ns cannot be stamped apart")

    # (topic, schema name, rows, payloads) in per-step publishing order
    streams: list[tuple[str, str, np.ndarray, list[bytes]]] = []

    def ros(topic: str, schema: str, rows: np.ndarray, values: ArrayF) -> None:
        if len(rows):
            streams.append((topic, schema, rows, encode_ros2(schema, stamps[rows], values, frame_id)))

    def fox(topic: str, rows: np.ndarray, values: ArrayF) -> None:
        if foxglove and len(rows):
            streams.append((topic, _FOXGLOVE_POSE, rows, encode_pose_in_frame(stamps[rows], frame_id, values)))

    every = np.arange(n)
    if truth is not None:
        pose = _pose_values(truth)
        ros(topics.truth_pose, _POSE, every, pose)
        ros(topics.truth_twist, _TWIST, every, _twist_values(truth))
        fox(topics.foxglove_truth_pose, every, pose)
    if measurements is not None:
        keep = valid if valid is not None else ~np.isnan(measurements).any(axis=1)
        rows = np.flatnonzero(keep)
        pose = _pose_values(measurements[rows])
        ros(topics.measured_pose, _POSE, rows, pose)
        fox(topics.foxglove_measured_pose, rows, pose)
    if estimates is not None:
        rows = every if estimate_mask is None else np.flatnonzero(estimate_mask)
        est = estimates[rows]
        pose = _pose_values(est)
        ros(topics.estimated_pose, _POSE, rows, pose)
        ros(topics.estimated_twist, _TWIST, rows, _twist_values(est))
        if covariances is not None:
            values = np.concatenate([pose, ros_pose_covariance(covariances[rows])], axis=1)
            ros(topics.estimated_pose_covariance, _POSE_COV, rows, values)
        fox(topics.foxglove_estimated_pose, rows, pose)

    recording_meta = {
        "format": RECORDING_FORMAT,
        "format_version": str(RECORDING_FORMAT_VERSION),
        "frame_id": frame_id,
        "start_epoch_ns": str(int(start_epoch_ns)),
        "n_steps": str(n),
        "topics": json.dumps({k: v for k, v in asdict(topics).items() if foxglove or not k.startswith("foxglove")}),
        "time_convention": "header.stamp = log_time = publish_time = start_epoch_ns + round(t * 1e9) ns",
        "quaternion_convention": "ROS x, y, z, w; body to world",
        "twist_frame": f"world-frame linear and angular velocity, expressed in '{frame_id}'",
        "covariance_convention": (
            "row-major 6x6 of (x, y, z, rot_x, rot_y, rot_z); rotation = world-frame rotation-vector "
            "error dtheta with q_true = exp(dtheta/2) (x) q_est"
        ),
    }
    with atomic_path(path, suffix=".mcap") as tmp:
        with open(tmp, "wb") as fh:
            writer = Writer(fh, chunk_size=chunk_size, compression=COMPRESSIONS[compression])
            writer.start(profile="ros2", library=f"fkn-bench/{__version__}; {MCAP_LIBRARY}")
            writer.add_metadata("fkn_bench.recording", recording_meta)
            for name, record in (metadata or {}).items():
                writer.add_metadata(name, {str(k): str(v) for k, v in record.items()})
            schema_ids: dict[str, int] = {}
            for schema in dict.fromkeys(s[1] for s in streams):
                if schema == _FOXGLOVE_POSE:
                    schema_ids[schema] = writer.register_schema(schema, "jsonschema", FOXGLOVE_SCHEMAS[schema])
                else:
                    schema_ids[schema] = writer.register_schema(schema, "ros2msg", ros2_schema_text(schema).encode())
            channels = [
                writer.register_channel(topic, "json" if schema == _FOXGLOVE_POSE else "cdr", schema_ids[schema])
                for topic, schema, _, _ in streams
            ]
            # messages in step order, streams in publishing order within a step; sequence = index in the stream
            queue = sorted(
                (step, i, q) for i, (_, _, rows, _) in enumerate(streams) for q, step in enumerate(rows.tolist())
            )
            stamp_of = stamps.tolist()
            for step, i, q in queue:
                stamp = stamp_of[step]
                writer.add_message(channels[i], log_time=stamp, data=streams[i][3][q], publish_time=stamp, sequence=q)
            writer.finish()
        size = tmp.stat().st_size
    return RecordingSummary(
        path=Path(path),
        n_steps=n,
        message_counts={topic: len(rows) for topic, _, rows, _ in streams},
        size_bytes=size,
        write_seconds=time.perf_counter() - started,
        topics=topics,
    )


def episode_metadata(
    episode: Mapping[str, str],
    *,
    scenario: Any = None,
    estimator: Any = None,
    extra: Mapping[str, Mapping[str, str]] | None = None,
) -> dict[str, Mapping[str, str]]:
    """The metadata records of a recorded episode (see the module docstring), then ``extra``; an
    ``estimator`` given as a mapping is taken as it is."""
    metadata: dict[str, Mapping[str, str]] = {}
    if scenario is not None:
        fields = {key: json.dumps(value) for key, value in scenario.to_dict().items()}
        metadata["fkn_bench.scenario"] = {**fields, "config_hash": scenario.config_hash()}
    metadata["fkn_bench.episode"] = dict(episode)
    if isinstance(estimator, Mapping):
        metadata["fkn_bench.estimator"] = {str(k): v if isinstance(v, str) else json.dumps(v) for k, v in estimator.items()}
    elif estimator is not None:
        cls = type(estimator)
        record = {"name": str(getattr(estimator, "name", cls.__name__)), "class": f"{cls.__module__}:{cls.__qualname__}"}
        if callable(getattr(estimator, "to_config", None)):
            record["config"] = json.dumps(to_jsonable(estimator.to_config()))
        metadata["fkn_bench.estimator"] = record
    metadata["fkn_bench.provenance"] = provenance()
    metadata.update(extra or {})
    return metadata


def record_episode(
    path: str | Path,
    episodes: Any,
    estimates: Any = None,
    *,
    index: int = 0,
    estimator: Any = None,
    split: str | None = None,
    extra_metadata: Mapping[str, Mapping[str, str]] | None = None,
    **options: Any,
) -> RecordingSummary:
    """Record row ``index`` of ``episodes`` (an :class:`~fkn_bench.envs.Episodes`) and, when
    given, the matching row of ``estimates`` (:class:`~fkn_bench.estimators.Estimates`).

    Estimates are written where ``estimates.initialised`` is True. ``estimator`` (an
    :class:`~fkn_bench.estimators.Estimator`, or a mapping of strings) fills the
    ``fkn_bench.estimator`` metadata; ``options`` go to :func:`write_recording`.
    """
    if not 0 <= index < episodes.batch_size:
        raise ValueError(f"index must be in [0, {episodes.batch_size}) (got {index})")
    means = covariances = mask = None
    if estimates is not None:
        if estimates.means.shape[:2] != episodes.truth.shape[:2]:
            raise ValueError(
                f"estimates cover {estimates.means.shape[:2]} (batch, steps); the episodes {episodes.truth.shape[:2]}"
            )
        arrays = (estimates.means, estimates.error_covariances, estimates.initialised)
        means, covariances, mask = (None if a is None else a[index] for a in arrays)
    episode = {
        "seed": str(episodes.seeds[index]),
        "split": split or ("full" if episodes.start == 0 and episodes.n_steps == episodes.scenario.n_steps else "window"),
        "start_step": str(episodes.start),
        "n_steps": str(episodes.n_steps),
        "dt": repr(episodes.scenario.dt),
    }
    metadata = episode_metadata(episode, scenario=episodes.scenario, estimator=estimator, extra=extra_metadata)
    return write_recording(
        path,
        times=episodes.times,
        truth=episodes.truth[index],
        measurements=episodes.measurements[index],
        valid=episodes.valid[index],
        estimates=means,
        estimate_error_covariances=covariances,
        estimate_mask=mask,
        metadata=metadata,
        **options,
    )
