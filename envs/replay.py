"""Turn a recording (its topics read by :mod:`fkn_bench.recordings`, the file format) into
fkn-bench :class:`~fkn_bench.envs.Episodes` (one episode), on the scenario's time grid and with its
measurement model; ``AstrobeeReplay-v0`` (:mod:`fkn_bench.envs.astrobee_replay`) replays one.

:func:`read_recording` reads the truth (and optionally a measurement topic) once and returns a
:class:`RecordedTrajectory`; its :meth:`~RecordedTrajectory.episodes` builds the ``Episodes`` for
an episode seed. :func:`load_episodes` does both in one call.

How the episode is built:

* **Topics.** ``truth_topic=None`` picks, in order: the truth topic named in an fkn-bench
  recording's metadata; else the single topic named ``<robot>/loc/truth/pose`` (Astrobee's
  ground truth, e.g. ``/loc/truth/pose`` or ``/honey/loc/truth/pose``). Pose topics may be
  ``PoseStamped``, ``PoseWithCovarianceStamped``, ``Odometry`` (ROS 1 or 2) or JSON
  ``foxglove.PoseInFrame`` (see :mod:`fkn_bench.recordings.base` for validation and repairs), in
  an MCAP file, a ROS 1 bag or a ROS 2 bag (:func:`~fkn_bench.recordings.open_recording`).
* **Time grid.** Step ``k`` is at ``t0 + k dt`` where ``t0`` is the first truth stamp and ``dt``
  the scenario's (``dt=None``), a given number of seconds, or ``"native"`` (the median interval
  of the truth messages, to the ns). The grid ends at the last truth stamp. ``Episodes.times``
  counts from 0 (``k dt``) and ``Episodes.start`` is 0.
* **Truth resampling.** Where a grid time equals a message stamp to the ns, that message's values
  are used unchanged (so an fkn-bench recording replays bit-exactly); elsewhere the attitude is
  interpolated by slerp (shortest arc) between the neighbouring messages and position and twist
  linearly.
* **Twist.** ``twist_topic="auto"`` uses, in order: the twist of an ``Odometry`` truth topic; the
  ``TwistStamped`` topic next to the truth topic (``.../pose`` -> ``.../twist``, e.g. Astrobee's
  ``loc/truth/twist``); else finite differences. ``twist_topic=None`` always uses finite
  differences; a name uses that topic. Twists are interpolated linearly onto the grid (held
  constant beyond their first/last stamp). Finite differences are central differences of the
  truth messages (one-sided at the ends) before resampling: velocity from positions, world-frame
  angular velocity from ``log(q_{i+1} q_{i-1}^-1) / (t_{i+1} - t_{i-1})``.
  The report says which source was used (``twist_source``).
* **Twist frame.** fkn-bench states use world-frame rates. ``twist_frame="auto"`` treats a
  ``TwistStamped`` whose ``header.frame_id`` is empty, ``"world"`` or the truth pose's frame as
  world-frame (Astrobee's simulator publishes world-frame twists in "world"), and any other
  frame, like ``Odometry``'s ``child_frame_id`` (ROS REP 105), as the body frame, rotated into
  the world frame with the true attitude. ``"world"`` / ``"body"`` force either.
* **Measurements.** Without ``measurement_topic`` they are synthesised from the (resampled) truth
  with the scenario's noise model, schedule and corruptions, exactly as
  :func:`~fkn_bench.envs.generate_episodes` does for the same seed. With one, its poses are used
  as they are (no interpolation, no sign change), each assigned to the grid step nearest to its
  stamp; several in one step keep the last; ones outside the grid are dropped (both reported).
* **Scenario.** ``scenario=None`` uses the scenario stored in an fkn-bench recording's metadata,
  else ``ds1``; the returned scenario is that one with ``name="replay-<file stem>"``, the grid's
  ``dt`` and ``n_steps`` (and, for recordings too short for its split, 2 validation and 2 test
  steps; at least 6 steps are needed). Only ``dt``, ``n_steps`` and, for synthesised measurements, the noise
  and schedule fields describe the replayed data.
* **Plausibility.** The resampled true states (twists included) must be plausible
  (:mod:`fkn_bench.recordings.plausibility`: finite, positions within +-1e6 m, rates within
  +-1e3 rad/s and m/s, unit quaternions within ``quaternion_tolerance``), else a
  :class:`~fkn_bench.recordings.RecordingError` names the file, the truth topic and the step:
  never scored, an overflow would read as the estimator diverging.
"""

from __future__ import annotations

import json
import re
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fkn_bench.envs.episodes import Episodes, measurement_covariances
from fkn_bench.envs.measurements import MeasurementGenerator
from fkn_bench.geometry import quaternion as quat
from fkn_bench.limits import ESTIMATION_BYTES_PER_STEP, check_memory
from fkn_bench.recordings.plausibility import QUATERNION_TOLERANCE, first_implausible
from fkn_bench.recordings.opening import open_recording
from fkn_bench.recordings.base import (
    PoseSeries,
    Recording,
    RecordingError,
    RecordingRepairWarning,
    TopicNotFoundError,
    POSE_TYPES,
)
from fkn_bench.scenarios import ConfigError, Scenario, get_scenario
from fkn_bench.types import ArrayB, ArrayF, Bool, Float

__all__ = [
    "ASTROBEE_TRUTH_PATTERN", "ReplayReport", "RecordedTrajectory", "read_recording",
    "load_episodes", "resample_truth", "finite_difference_twist", "body_to_world"
]

ASTROBEE_TRUTH_PATTERN = re.compile(r"^(/[^/]+)*/loc/truth/pose$|^loc/truth/pose$")
"""Topic names taken as Astrobee ground truth: ``[/<robot>]/loc/truth/pose``."""

_WORLD_FRAMES = ("", "world")


@dataclass(frozen=True)
class ReplayReport:
    """Where a replayed episode came from and what was done to it.

    Attributes:
        path: the recording.
        truth_topic, truth_type: the truth topic and its type.
        truth_messages: truth messages used.
        truth_rate_hz: median message rate of the truth topic.
        time_source: ``"header"`` or ``"log"`` (all header stamps zero).
        twist_source: ``"topic <name>"``, ``"odometry <name>"`` or ``"finite differences"``.
        twist_frame: ``"world"`` or ``"body"`` (rotated into the world frame).
        measurement_source: ``"topic <name>"`` or ``"synthesised (<scenario> noise model)"``.
        interpolated_steps: grid steps whose truth was interpolated (0: every step is a message).
        repairs: repairs applied (also issued as :class:`RecordingRepairWarning`).
        notes: other remarks (fallbacks, dropped measurements, gaps).
        metadata: the recording's metadata records.
    """

    path: Path
    truth_topic: str
    truth_type: str
    truth_messages: int
    truth_rate_hz: float
    time_source: str
    twist_source: str
    twist_frame: str
    measurement_source: str
    interpolated_steps: int
    repairs: tuple[str, ...]
    notes: tuple[str, ...]
    metadata: Mapping[str, Mapping[str, str]]

    def summary(self) -> str:
        """Several lines for a terminal."""
        lines = [
            f"recording {self.path}",
            f"  truth        {self.truth_topic} ({self.truth_type}, {self.truth_messages} messages, "
            f"{self.truth_rate_hz:.4g} Hz, {self.time_source} stamps)",
            f"  twist        {self.twist_source} ({self.twist_frame} frame)",
            f"  measurements {self.measurement_source}",
            f"  resampling   {self.interpolated_steps} step(s) interpolated",
        ]
        lines += [f"  repair: {r}" for r in self.repairs]
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


@dataclass(frozen=True, eq=False)
class RecordedTrajectory:
    """The truth of a recording on the scenario's time grid, and its measurements if recorded.

    Attributes:
        scenario: the replay scenario (``dt``, ``n_steps`` = T, noise model).
        times: ``(T,)`` ``k * dt``, s.
        truth: ``(T, 13)`` true states (world-frame rates).
        measurements: ``(T, 7)`` recorded measurements (NaN where missing) or None (synthesised).
        valid: ``(T,)`` validity of the recorded measurements, or None.
        start_stamp_ns: stamp of step 0 in the recording, ns.
        report: :class:`ReplayReport`.
        measurement_covariances: ``(T, 6, 6)`` the covariances the recorded measurements state
            (``PoseWithCovarianceStamped``, ``Odometry``; error order ``[dtheta, dr]``, NaN where a
            step has none), or None.
    """

    scenario: Scenario
    times: Float[ArrayF, "T"]
    truth: Float[ArrayF, "T 13"]
    measurements: Float[ArrayF, "T 7"] | None
    valid: Bool[ArrayB, "T"] | None
    start_stamp_ns: int
    report: ReplayReport
    measurement_covariances: Float[ArrayF, "T 6 6"] | None = None

    @property
    def n_steps(self) -> int:
        return len(self.times)

    def episodes(self, seed: int = 0) -> Episodes:
        """The replayed episode as :class:`~fkn_bench.envs.Episodes` with batch size 1.

        ``seed`` seeds the synthesised measurements (and is recorded in ``Episodes.seeds``);
        recorded measurements do not depend on it.
        """
        seed = int(seed)
        if seed < 0:
            raise ValueError(f"seed must be a non-negative integer (got {seed})")
        covariances = None
        if self.measurements is not None and self.valid is not None:
            measurements, valid = self.measurements.copy(), self.valid.copy()
            if self.measurement_covariances is not None:
                covariances = self.measurement_covariances[None].copy()
        else:
            pose = np.ascontiguousarray(self.truth[None, :, :7].transpose(0, 2, 1))
            generated, valid_b = MeasurementGenerator(self.scenario, [seed]).generate(pose, 0)
            measurements, valid = generated.transpose(0, 2, 1)[0], valid_b[0]
            if self.scenario.measurement_covariance:
                covariances = measurement_covariances(self.scenario, 0, valid[None])
        return Episodes(
            scenario=self.scenario,
            seeds=(seed,),
            start=0,
            times=self.times.copy(),
            truth=self.truth[None].copy(),
            measurements=np.ascontiguousarray(measurements[None]),
            valid=valid[None].copy(),
            measurement_covariances=covariances,
        )


# ---------------------------------------------------------------------------- numerics
def _locate(stamps: np.ndarray, grid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """For each grid time: exact-hit flag and sample, else the bracketing samples and fraction."""
    n = len(stamps)
    pos = np.searchsorted(stamps, grid, side="left")
    hit = (pos < n) & (stamps[np.minimum(pos, n - 1)] == grid)
    hi = np.clip(pos, 1, n - 1)
    lo = hi - 1
    span = (stamps[hi] - stamps[lo]).astype(np.float64)
    frac = np.clip((grid - stamps[lo]).astype(np.float64) / span, 0.0, 1.0)
    exact = np.where(hit, np.minimum(pos, n - 1), -1)
    return exact, lo, hi, frac


def resample_truth(stamps_ns: np.ndarray, poses: Float[ArrayF, "M 7"], grid_ns: np.ndarray) -> tuple[Float[ArrayF, "N 7"], int]:
    """Poses ``(N, 7)`` at ``grid_ns``: samples where the stamps match exactly, slerp / linear
    interpolation between neighbours elsewhere (clamped at the ends).

    Returns ``(poses (T, 7), number of interpolated grid steps)``.
    """
    exact, lo, hi, frac = _locate(stamps_ns, grid_ns)
    interp = exact < 0
    out = np.empty((len(grid_ns), 7))
    out[:, :4] = poses[exact, :4]  # rows to interpolate are overwritten below
    if interp.any():
        out[interp, :4] = quat.slerp(poses[lo[interp], :4], poses[hi[interp], :4], frac[interp])
    out[:, 4:] = _resample_linear(stamps_ns, poses[:, 4:], grid_ns)
    return out, int(interp.sum())


def _resample_linear(stamps_ns: np.ndarray, values: ArrayF, grid_ns: np.ndarray) -> ArrayF:
    """Linear interpolation (exact at matching stamps, held beyond the ends)."""
    if len(stamps_ns) == 1:
        return np.repeat(values, len(grid_ns), axis=0)
    exact, lo, hi, frac = _locate(stamps_ns, grid_ns)
    out = values[lo] + frac[:, None] * (values[hi] - values[lo])
    out[exact >= 0] = values[exact[exact >= 0]]
    return out


def body_to_world(attitudes: Float[ArrayF, "N 4"], twists: Float[ArrayF, "N 6"]) -> Float[ArrayF, "N 6"]:
    """Body-frame twists ``[angular(3), linear(3)]`` rotated into the world frame by ``attitudes``
    (body to world, wxyz)."""
    return np.concatenate([quat.rotate(attitudes, twists[:, :3]), quat.rotate(attitudes, twists[:, 3:])], axis=1)


def finite_difference_twist(stamps_ns: np.ndarray, poses: Float[ArrayF, "N 7"]) -> Float[ArrayF, "N 6"]:
    """World-frame twists ``(N, 6)`` = ``[w(3), v(3)]`` of poses ``(N, 7)`` by central differences
    (one-sided at the ends); ``w`` from ``log(q_{i+1} (x) q_{i-1}^-1) / (t_{i+1} - t_{i-1})``."""
    n = len(stamps_ns)
    if n < 2:
        raise ValueError("finite differences need at least two poses")
    t = (stamps_ns - stamps_ns[0]).astype(np.float64) / 1e9
    nxt = np.minimum(np.arange(n) + 1, n - 1)
    prv = np.maximum(np.arange(n) - 1, 0)
    span = t[nxt] - t[prv]
    omega = quat.to_rotation_vector(quat.multiply(poses[nxt, :4], quat.conjugate(poses[prv, :4]))) / span[:, None]
    velocity = (poses[nxt, 4:] - poses[prv, 4:]) / span[:, None]
    return np.concatenate([omega, velocity], axis=1)


# ---------------------------------------------------------------------------- reading
def _recording_metadata(rec: Recording) -> tuple[dict[str, dict[str, str]], dict[str, str], Scenario | None, list[str]]:
    metadata = rec.metadata()
    notes: list[str] = []
    topics: dict[str, str] = {}
    scenario = None
    recording = metadata.get("fkn_bench.recording", {})
    try:
        topics = {str(k): str(v) for k, v in json.loads(recording.get("topics", "{}")).items()}
    except (ValueError, AttributeError):
        notes.append("the fkn_bench.recording metadata has an unreadable 'topics' entry; ignored")
    if stored := metadata.get("fkn_bench.scenario"):
        try:
            scenario = Scenario.from_dict({k: json.loads(v) for k, v in stored.items() if k != "config_hash"})
        except (ValueError, TypeError) as exc:
            notes.append(f"the stored scenario cannot be read ({exc}); using ds1")
    return metadata, topics, scenario, notes


def _pick_truth_topic(rec: Recording, recorded_topics: Mapping[str, str]) -> str:
    topics = rec.topics()
    named = recorded_topics.get("truth_pose")
    if named and named in topics:
        return named
    candidates = [t for t, info in topics.items() if ASTROBEE_TRUTH_PATTERN.match(t) and info.type_name in POSE_TYPES]
    if len(candidates) == 1:
        return candidates[0]
    if len(candidates) > 1:
        raise RecordingError(
            f"{rec.path}: several ground-truth topics ({', '.join(candidates)}); pass truth_topic= to choose one",
            path=rec.path,
        )
    raise TopicNotFoundError(
        f"{rec.path}: no truth topic given and none named <robot>/loc/truth/pose (Astrobee's ground truth) with a "
        f"pose type; pass truth_topic=. {rec.describe_topics()}",
        path=rec.path,
    )


def _grid(first: int, last: int, dt: float) -> np.ndarray:
    steps = int(np.floor((last - first) / (dt * 1e9) + 1e-6)) + 1
    return first + np.round(np.arange(steps) * dt * 1e9).astype(np.int64)


def read_recording(
    path: str | Path,
    *,
    truth_topic: str | None = None,
    measurement_topic: str | None = None,
    twist_topic: str | None = "auto",
    scenario: str | Scenario | None = None,
    dt: float | str | None = None,
    repair: bool = False,
    time_source: str = "auto",
    twist_frame: str = "auto",
    quaternion_tolerance: float = 1e-6,
    warn: bool = True,
) -> RecordedTrajectory:
    """Read a recording's truth (and measurements) onto a uniform time grid.

    Args:
        path: the recording: an ``.mcap`` file (ROS 2, ROS 1 or Foxglove JSON poses), a ROS 1
            ``.bag``, a ROS 2 bag directory or ``.db3`` file (:func:`~fkn_bench.recordings.open_recording`).
        truth_topic: pose topic of the ground truth; None: see module docstring (fkn-bench
            recordings and Astrobee's ``<robot>/loc/truth/pose`` need none).
        measurement_topic: pose topic of the measurements, used as is; None: synthesise them.
        twist_topic: ``"auto"``, None (finite differences) or a ``TwistStamped``/``Odometry`` topic.
        scenario: base scenario (name or :class:`Scenario`); None: the recording's, else ``ds1``.
        dt: grid step, s; None: the scenario's; ``"native"``: the truth's median interval.
        repair: apply the documented repairs instead of raising (:mod:`fkn_bench.recordings.base`,
            :mod:`fkn_bench.recordings.reader`).
        time_source: ``"auto"`` (header stamps, log time if all are zero), ``"header"``, ``"log"``.
        twist_frame: ``"auto"``, ``"world"`` or ``"body"`` (see module docstring).
        quaternion_tolerance: largest accepted ``|norm - 1|`` of a recorded quaternion.
        warn: issue each repair as a :class:`RecordingRepairWarning`.

    Raises:
        RecordingError: (and its subclass ``TopicNotFoundError``) naming file, topic and message.
    """
    if twist_frame not in ("auto", "world", "body"):
        raise ValueError(f"twist_frame must be 'auto', 'world' or 'body' (got {twist_frame!r})")
    rec = open_recording(path, repair=repair)
    metadata, recorded_topics, stored_scenario, notes = _recording_metadata(rec)
    base = get_scenario(scenario) if scenario is not None else (stored_scenario or get_scenario("ds1"))

    truth_name = truth_topic if truth_topic is not None else _pick_truth_topic(rec, recorded_topics)
    truth_info = rec.require_topic(truth_name, "truth")
    twist_name = None if twist_topic == "auto" else twist_topic
    if twist_topic == "auto" and truth_info.type_name != "nav_msgs/Odometry" and truth_name.endswith("pose"):
        twist_name = truth_name[: -len("pose")] + "twist"  # the TwistStamped topic next to the truth, if any
        info = rec.topics().get(twist_name)
        if info is None or info.type_name != "geometry_msgs/TwistStamped" or info.message_count == 0:
            twist_name = None
    elif twist_name is not None:
        rec.require_topic(twist_name, "twist")
    rec.prefetch([t for t in (truth_name, twist_name, measurement_topic) if t])
    repairs = list(rec.repairs)

    def read(series: Any) -> Any:
        repairs.extend(series.repairs)
        notes.extend(series.notes)
        return series

    truth = read(rec.read_poses(truth_name, role="truth", time_source=time_source,
                                quaternion_tolerance=quaternion_tolerance))
    if len(truth.stamps_ns) < 2:
        raise RecordingError(f"{rec.path}: truth topic {truth_name!r} has fewer than 2 usable messages", path=rec.path, topic=truth_name)
    intervals = np.diff(truth.stamps_ns)
    rate = 1e9 / float(np.median(intervals))

    if dt is None:
        step = base.dt
    elif dt == "native":
        step = float(np.round(np.median(intervals))) / 1e9
    else:
        try:
            step = float(dt)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            raise ValueError(f"dt must be a number of seconds, None or 'native' (got {dt!r})") from None
        if not np.isfinite(step) or step <= 0:
            raise ValueError(f"dt must be a finite number > 0 (got {dt!r})")
    span_s = (int(truth.stamps_ns[-1]) - int(truth.stamps_ns[0])) / 1e9
    check_memory((span_s / step + 1) * ESTIMATION_BYTES_PER_STEP,
                 f"replaying {rec.path}: its truth spans {span_s:.6g} s, {span_s / step + 1:.6g} steps of {step:g} s",
                 "a larger time step (--dt SECONDS) or a recording without long gaps (--repair does not close them)")
    grid = _grid(int(truth.stamps_ns[0]), int(truth.stamps_ns[-1]), step)
    if len(grid) < 2:
        raise RecordingError(
            f"{rec.path}: truth topic {truth_name!r} spans {(truth.stamps_ns[-1] - truth.stamps_ns[0]) / 1e9:.6g} s, "
            f"less than one step of {step:g} s",
            path=rec.path, topic=truth_name,
        )
    largest_gap = float(intervals.max()) / 1e9
    if largest_gap > 5 * max(step, float(np.median(intervals)) / 1e9):
        notes.append(f"{truth_name}: the truth has gaps of up to {largest_gap:.6g} s; interpolated across them")

    # twist: a topic, the truth's Odometry twist, or finite differences (see the module docstring)
    source, frame, twist_stamps = "finite differences", "world", truth.stamps_ns
    if twist_name is not None:
        tw = read(rec.read_twists(twist_name, role="twist", time_source=time_source))
        twists_raw, twist_stamps, source = tw.twists, tw.stamps_ns, f"topic {twist_name}"
        world = ("",) if tw.type_name == "nav_msgs/Odometry" else _WORLD_FRAMES
        frame = "world" if tw.frame_id in (*world, truth.frame_id) else "body"
    elif twist_topic is not None and truth.twists is not None:
        twists_raw, source = truth.twists, f"odometry {truth_name}"
        frame = "world" if truth.child_frame_id in ("", truth.frame_id) else "body"
    else:
        twists_raw = finite_difference_twist(truth.stamps_ns, truth.poses)
    if twist_frame != "auto" and source != "finite differences":
        frame = twist_frame

    poses, interpolated = resample_truth(truth.stamps_ns, truth.poses, grid)
    twists = _resample_linear(twist_stamps, twists_raw, grid)
    beyond = int(np.sum((grid < twist_stamps[0]) | (grid > twist_stamps[-1])))
    if beyond and twist_stamps is not truth.stamps_ns:
        notes.append(f"{twist_name}: {beyond} step(s) lie outside the twist messages; held their first/last value")
    if frame == "body":
        twists = body_to_world(poses[:, :4], twists)
    states = np.concatenate([poses, twists], axis=1)
    implausible = first_implausible(states, quaternion_tolerance=max(quaternion_tolerance, QUATERNION_TOLERANCE))
    if implausible is not None:  # e.g. a finite-difference velocity of two poses 1 ns apart
        (k,), problem = implausible
        raise RecordingError(
            f"{rec.path}: the true state of step {k} (t = {k * step:.6g} s after the first truth message; truth "
            f"{truth_name!r}, twist from {source}) is implausible: {problem} (fkn_bench.recordings.plausibility)",
            path=rec.path, topic=truth_name,
        )

    # measurements
    measurements = valid = covariances = None
    if measurement_topic is not None:
        meas = read(rec.read_poses(measurement_topic, role="measurement", time_source=time_source,
                                   quaternion_tolerance=quaternion_tolerance))
        measurements, valid, covariances = _snap_measurements(meas, grid, step, notes)
        measurement_source = f"topic {measurement_topic}"
    else:
        measurement_source = f"synthesised ({base.name} noise model)"

    fields = {
        "name": f"replay-{rec.path.stem}",
        "description": f"replay of {rec.path.name} (truth {truth_name}; {measurement_source}); base scenario {base.name}",
        "dt": step,
        "n_steps": len(grid),
    }
    try:
        replay_scenario = base.replace(**fields)
    except ConfigError:
        # too short for the base split: keep 2 steps each for validation and test
        n = len(grid)
        short_split = ((n - 4) / n, 2 / n, 2 / n)
        try:
            replay_scenario = base.replace(**fields, split=short_split)
        except ConfigError as exc:
            raise RecordingError(
                f"{rec.path}: the recording gives {n} steps of {step:g} s, too few for a scenario ({exc})",
                path=rec.path, topic=truth_name,
            ) from None
        notes.append(f"{n} steps are too few for the split {base.split}; used train/val/test = {n - 4}/2/2 steps")
    report = ReplayReport(
        path=rec.path,
        truth_topic=truth_name,
        truth_type=truth.type_name,
        truth_messages=len(truth.stamps_ns),
        truth_rate_hz=rate,
        time_source=truth.time_source,
        twist_source=source,
        twist_frame=frame,
        measurement_source=measurement_source,
        interpolated_steps=interpolated,
        repairs=tuple(repairs),
        notes=tuple(notes),
        metadata=metadata,
    )
    if warn:
        for repair in repairs:
            warnings.warn(f"{rec.path}: {repair}", RecordingRepairWarning, stacklevel=2)
    return RecordedTrajectory(
        scenario=replay_scenario,
        times=np.arange(len(grid)) * step,
        truth=states,
        measurements=measurements,
        valid=valid,
        start_stamp_ns=int(grid[0]),
        report=report,
        measurement_covariances=covariances,
    )


def _snap_measurements(series: PoseSeries, grid: np.ndarray, dt: float,
                       notes: list[str]) -> tuple[ArrayF, ArrayB, ArrayF | None]:
    """Assign each measurement (and the covariance it states, if its type carries one) to the
    nearest grid step (the last one wins a step); remarks go to ``notes``."""
    n = len(grid)
    k = np.floor((series.stamps_ns - grid[0]).astype(np.float64) / (dt * 1e9) + 0.5).astype(np.int64)
    inside = (k >= 0) & (k < n)
    if not inside.all():
        notes.append(f"{series.topic}: dropped {int((~inside).sum())} measurement(s) outside the truth's time span")
    k_in = k[inside]
    poses = series.poses[inside]
    measurements = np.full((n, 7), np.nan)
    valid = np.zeros(n, dtype=bool)
    measurements[k_in] = poses  # later rows win a shared step (stamps are sorted)
    valid[k_in] = True
    covariances = None
    if series.covariances is not None:
        covariances = np.full((n, 6, 6), np.nan)
        covariances[k_in] = series.covariances[inside]
    shared = len(k_in) - int(valid.sum())
    if shared:
        notes.append(f"{series.topic}: {shared} measurement(s) shared a step with a later one; kept the latest")
    if len(k_in):
        offset = np.abs(series.stamps_ns[inside] - grid[k_in]).max() / 1e9
        if offset > 1e-6:
            notes.append(f"{series.topic}: measurements moved to the nearest step (up to {offset * 1e3:.4g} ms)")
    return measurements, valid, covariances


def load_episodes(path: str | Path, *, seed: int = 0, **options: Any) -> Episodes:
    """``read_recording(path, **options).episodes(seed)``: the recording as
    :class:`~fkn_bench.envs.Episodes` (batch 1); ``seed`` seeds synthesised measurements."""
    return read_recording(path, **options).episodes(seed)
