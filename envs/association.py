"""External estimates (another program's output) put onto a replayed truth's time grid, so that
fkn-bench scores them with the same metrics as its own estimators.

An external estimate comes from a pose topic of the recording (``PoseStamped``,
``PoseWithCovarianceStamped``, ``Odometry``: :func:`series_from_topic`) or from a text file (TUM or
CSV, :mod:`fkn_bench.recordings.trajectories`: :func:`series_from_file`) as an
:class:`ExternalSeries` at its own stamps; :func:`associate` puts it onto the truth's grid
(:mod:`fkn_bench.envs.replay`: step ``k`` at ``t0 + k dt``, ``t0`` the first truth stamp) and
:func:`align_se3` optionally aligns it to the truth.

* **Twist.** From the estimate when it has one: an ``Odometry`` topic's twist, the
  ``TwistStamped`` topic next to a pose topic (``.../pose`` -> ``.../twist``, Astrobee's
  ``loc/pose`` and ``loc/twist``; the rule :mod:`fkn_bench.envs.replay` uses for the truth), or a
  CSV file's ``wx .. vz`` columns (world frame). A body-frame twist (an ``Odometry`` whose
  ``child_frame_id`` is neither empty nor its ``frame_id``, a ``TwistStamped`` whose ``frame_id`` is
  neither empty, ``"world"`` nor the pose's frame) is rotated into the world frame with the
  estimated attitude at its stamp. Without one: central finite differences of the estimated poses
  at their stamps (one-sided at the ends; :func:`fkn_bench.envs.replay.finite_difference_twist`,
  the truth's rule).
* **Association on the truth's clock.** Grid step ``k`` (time ``g_k``) is *associated* when it is
  an estimate stamp, or lies between two consecutive estimate stamps ``s_i < g_k < s_{i+1}`` with
  ``g_k - s_i <= tolerance`` and ``s_{i+1} - g_k <= tolerance``; its estimate is interpolated
  there: slerp (shortest arc) of the attitude, linear position and twist
  (:func:`fkn_bench.envs.replay.resample_truth`, the truth's interpolation, exact where the stamps
  match to the ns). The default tolerance is :data:`DEFAULT_TOLERANCE_INTERVALS` (2) times the
  estimate's median stamp interval: an estimate published at a steady rate is interpolated
  between any two consecutive messages, and a gap of more than two of its periods is not bridged.
  Nothing is extrapolated.
* **Steps without an estimate** are scored as fkn-bench scores its own estimators there (the
  metrics score every step; ``Estimates.initialised`` tells only the reader):
  before the estimate's first stamp, the prior of an estimator that has not initialised
  (identity attitude, zero position and twist; ``initialised`` False) -- the output of
  fkn-bench's filters before their first usable measurement, which a recording of them omits;
  from its first stamp on, a step that is not associated (a gap wider than the tolerance, or after
  the last stamp) holds the latest estimate at or before it (zero-order hold: what a consumer of
  the topic would have had; ``initialised`` True). The counts are in :class:`AssociatedEstimate`'s
  notes.
* **Alignment** (optional, :func:`align_se3`): the rotation and translation that carry the
  associated estimated positions onto the true ones in the least-squares sense (Umeyama 1991,
  without scale: :func:`fkn_bench.geometry.alignment.umeyama`). Where the true positions stay
  within :data:`MIN_PLANAR_SPREAD` (0.1 m RMS) of one line -- an Astrobee tumbling in place, or
  drifting straight, as every simulated scenario -- positions leave the rotation about that line
  to their noise, so the rotation is the mean of ``R_true R_est^T`` over the associated attitudes
  instead (:func:`fkn_bench.geometry.alignment.attitude_alignment`; same body frame assumed) and
  the translation from the positions; the report names the method. The transform is applied to
  every estimated step: ``r' = R r + t``, ``q' = q_R (x) q`` (the estimate's world frame rotated into the truth's),
  world-frame rates and velocities ``R w``, ``R v``, pose covariances ``diag(R, R) P diag(R, R)^T``.
  For estimates in another world frame (a map frame); it hides a constant offset of an estimate in
  the truth's frame, so it is off by default.
* **Covariances.** A CSV file's pose covariances are carried on the grid (interpolated linearly
  element-wise, held with the pose) for reports; the metrics' NEES needs the 12x12 covariance of
  the full error ``[dtheta, dr, dw, dv]``, which a pose covariance is not, so external rows have no
  NEES.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from fkn_bench.envs.replay import _resample_linear, body_to_world, finite_difference_twist, resample_truth
from fkn_bench.geometry import quaternion as quat
from fkn_bench.geometry.alignment import RigidTransform, attitude_alignment, umeyama
from fkn_bench.linalg import symmetrize
from fkn_bench.recordings import RecordingError
from fkn_bench.recordings.trajectories import TEXT_QUATERNION_TOLERANCE, read_trajectory
from fkn_bench.types import ArrayB, ArrayF, Bool, Float

__all__ = [
    "DEFAULT_TOLERANCE_INTERVALS", "EXTERNAL_PREFIX", "MIN_PLANAR_SPREAD", "ExternalSeries", "AssociatedEstimate", "series_from_topic",
    "series_from_file", "associate", "align_se3", "grid_stamps",
]

DEFAULT_TOLERANCE_INTERVALS = 2.0
"""Default association tolerance, in median intervals of the estimate's stamps."""
EXTERNAL_PREFIX = "external:"
"""Row names of external estimates: ``external:<topic>`` or ``external:<file name>``."""

MIN_PLANAR_SPREAD = 0.1
"""Smallest RMS distance (m) of the true positions from their best-fit line for which
:func:`align_se3` takes the rotation from the positions (module docstring)."""

_WORLD_FRAMES = ("", "world")
_PRIOR = np.array([1.0] + [0.0] * 12)


@dataclass(frozen=True, eq=False)
class ExternalSeries:
    """An external estimate at its own stamps.

    Attributes:
        name: its row name (``external:/loc/pose``, ``external:myfilter.tum``).
        source: where it came from, in words.
        stamps_ns: ``(N,)`` strictly increasing stamps, ns.
        poses: ``(N, 7)`` ``[qw, qx, qy, qz, rx, ry, rz]`` (unit quaternions, body to world).
        twist_stamps_ns, twists: ``(M,)`` stamps and ``(M, 6)`` world-frame twists ``[w, v]``.
        twist_source: where the twists came from, in words.
        covariances: ``(N, 6, 6)`` pose covariances of ``[dtheta, dr]``, or None.
        digest: SHA-256 (hex) of the data the series was read from (changes with the data).
    """

    name: str
    source: str
    stamps_ns: np.ndarray
    poses: Float[ArrayF, "N 7"]
    twist_stamps_ns: np.ndarray
    twists: Float[ArrayF, "M 6"]
    twist_source: str
    covariances: Float[ArrayF, "N 6 6"] | None = None
    digest: str = ""


def _world_twists(stamps_ns: np.ndarray, poses: ArrayF, twist_stamps_ns: np.ndarray, twists: ArrayF, body: bool) -> ArrayF:
    """``twists`` in the world frame: rotated with the estimated attitude at their stamps when ``body``."""
    if not body:
        return twists
    attitude = resample_truth(stamps_ns, poses, twist_stamps_ns)[0][:, :4]
    return body_to_world(attitude, twists)


def _digest(*arrays: Any) -> str:
    sha = hashlib.sha256()
    for array in arrays:
        if array is not None:
            sha.update(np.ascontiguousarray(array).tobytes())
    return sha.hexdigest()


def _check_length(series: Any, what: str) -> None:
    if len(series.stamps_ns) < 2:
        raise RecordingError(f"{what} has {len(series.stamps_ns)} usable estimate(s); at least 2 are needed to "
                             "interpolate", path=getattr(series, "path", None))


def series_from_topic(recording: Any, topic: str, *, time_source: str = "auto",
                      quaternion_tolerance: float = 1e-6) -> ExternalSeries:
    """The estimate published on pose topic ``topic`` of ``recording`` (a reader from
    :func:`fkn_bench.recordings.open_recording`), with its twist (module docstring)."""
    pose = recording.read_poses(topic, role="estimate", time_source=time_source,
                                quaternion_tolerance=quaternion_tolerance)
    _check_length(pose, f"{recording.path}: estimate topic {topic!r}")
    short = pose.type_name.split("/")[-1]
    twist_topic = topic[: -len("pose")] + "twist" if topic.endswith("pose") else None
    info = recording.topics().get(twist_topic) if twist_topic else None
    if pose.twists is not None:
        body = pose.child_frame_id not in ("", pose.frame_id)
        twists = _world_twists(pose.stamps_ns, pose.poses, pose.stamps_ns, pose.twists, body)
        stamps, source = pose.stamps_ns, f"odometry {topic} ({'body' if body else 'world'} frame)"
    elif info is not None and info.type_name == "geometry_msgs/TwistStamped" and info.message_count != 0:
        tw = recording.read_twists(twist_topic, role="estimate twist", time_source=time_source)
        body = tw.frame_id not in (*_WORLD_FRAMES, pose.frame_id)
        twists = _world_twists(pose.stamps_ns, pose.poses, tw.stamps_ns, tw.twists, body)
        stamps, source = tw.stamps_ns, f"topic {twist_topic} ({'body' if body else 'world'} frame)"
    else:
        twists, stamps, source = finite_difference_twist(pose.stamps_ns, pose.poses), pose.stamps_ns, "finite differences"
    return ExternalSeries(
        name=f"{EXTERNAL_PREFIX}{topic}", source=f"topic {topic} ({short}, {len(pose.stamps_ns)} messages)",
        stamps_ns=pose.stamps_ns, poses=pose.poses, twist_stamps_ns=stamps, twists=twists, twist_source=source,
        covariances=pose.covariances, digest=_digest(pose.stamps_ns, pose.poses, stamps, twists, pose.covariances),
    )


def series_from_file(path: str | Path, *, quaternion_tolerance: float = TEXT_QUATERNION_TOLERANCE) -> ExternalSeries:
    """The estimate in text file ``path`` (TUM or CSV, :func:`fkn_bench.recordings.trajectories.read_trajectory`)."""
    path = Path(path)
    series = read_trajectory(path, quaternion_tolerance=quaternion_tolerance)
    _check_length(series, str(path))
    if series.twists is not None:
        twists, source = series.twists, f"file columns {path.name} (world frame)"
    else:
        twists, source = finite_difference_twist(series.stamps_ns, series.poses), "finite differences"
    return ExternalSeries(
        name=f"{EXTERNAL_PREFIX}{path.name}", source=f"file {path} ({series.type_name}, {len(series.stamps_ns)} lines)",
        stamps_ns=series.stamps_ns, poses=series.poses, twist_stamps_ns=series.stamps_ns, twists=twists,
        twist_source=source, covariances=series.covariances,
        digest=_digest(series.stamps_ns, series.poses, twists, series.covariances),
    )


def grid_stamps(start_stamp_ns: int, times: Float[ArrayF, "T"]) -> np.ndarray:
    """The stamps (ns) of a replayed grid, ``start + round(t_k * 1e9)``: those
    :func:`fkn_bench.envs.replay.read_recording` resampled the truth at (``RecordedTrajectory``'s
    ``start_stamp_ns`` and ``times``)."""
    return int(start_stamp_ns) + np.round(np.asarray(times, dtype=np.float64) * 1e9).astype(np.int64)


@dataclass(frozen=True, eq=False)
class AssociatedEstimate:
    """An external estimate on the truth's grid (module docstring).

    Attributes:
        name, source, twist_source: as :class:`ExternalSeries`.
        states: ``(T, 13)`` estimated states (world-frame rates).
        initialised: ``(T,)`` False before the estimate's first stamp (the prior is scored there).
        associated: ``(T,)`` True where the estimate was interpolated within the tolerance.
        covariances: ``(T, 6, 6)`` pose covariances ``[dtheta, dr]`` or None.
        tolerance_s: the association tolerance used, s.
        alignment: the SE(3) alignment applied, or None.
        digest: SHA-256 (hex) of the series, the tolerance and the alignment.
    """

    name: str
    source: str
    twist_source: str
    states: Float[ArrayF, "T 13"]
    initialised: Bool[ArrayB, "T"]
    associated: Bool[ArrayB, "T"]
    covariances: Float[ArrayF, "T 6 6"] | None
    tolerance_s: float
    alignment: RigidTransform | None = None
    digest: str = ""

    @property
    def counts(self) -> dict[str, int]:
        """Steps associated, held (no estimate within the tolerance) and before the first estimate."""
        return {"associated": int(self.associated.sum()),
                "held": int((self.initialised & ~self.associated).sum()),
                "before_first_estimate": int((~self.initialised).sum())}

    def report(self) -> dict[str, Any]:
        """JSON-compatible description (stored in the cells' notes, printed by ``fkn-bench run``)."""
        out: dict[str, Any] = {"source": self.source, "twist": self.twist_source, "tolerance_s": self.tolerance_s,
                               "steps": len(self.states), **self.counts}
        if self.alignment is not None:
            a = self.alignment
            out["alignment"] = {"method": f"se3, rotation from the {a.method}", "rotation_deg": float(np.degrees(a.angle)),
                                "rotation_quaternion_wxyz": [float(v) for v in a.quaternion],
                                "translation_m": [float(v) for v in a.translation],
                                "rms_residual_m": a.rms_residual, "points": a.points}
        return out

    def summary(self) -> str:
        """A line or two for a terminal."""
        c = self.counts
        lines = [f"{self.name}: {self.source}; {c['associated']}/{len(self.states)} steps associated (tolerance "
                 f"{self.tolerance_s:.6g} s), {c['held']} held, {c['before_first_estimate']} before its first estimate "
                 f"(scored as the prior); twist from {self.twist_source}"]
        if self.alignment is not None:
            a = self.alignment
            t = ", ".join(f"{v:.6g}" for v in a.translation)
            lines.append(f"  aligned (SE(3), rotation from the {a.method}) over {a.points} steps: rotation {np.degrees(a.angle):.6g} deg, "
                         f"translation [{t}] m, residual RMS {a.rms_residual:.6g} m")
        return "\n".join(lines)


def associate(series: ExternalSeries, grid_ns: np.ndarray, *, tolerance_s: float | None = None) -> AssociatedEstimate:
    """``series`` on the grid ``grid_ns`` (``(T,)`` int64 stamps, ns; module docstring).

    Raises:
        ValueError: a tolerance that is not a positive number.
        RecordingError: no grid step is associated (e.g. the estimate is on another clock).
    """
    stamps = np.asarray(series.stamps_ns, dtype=np.int64)
    grid = np.asarray(grid_ns, dtype=np.int64)
    if tolerance_s is None:
        tolerance_s = DEFAULT_TOLERANCE_INTERVALS * float(np.median(np.diff(stamps))) / 1e9
    elif not (np.isfinite(tolerance_s) and tolerance_s > 0):
        raise ValueError(f"the association tolerance must be a positive number of seconds (got {tolerance_s!r})")
    tolerance_ns = float(tolerance_s) * 1e9
    n = len(stamps)
    before = np.searchsorted(stamps, grid, side="right") - 1  # latest stamp <= g, -1 if none
    has = before >= 0
    prev = np.maximum(before, 0)
    nxt = np.minimum(prev + 1, n - 1)
    exact = has & (stamps[prev] == grid)
    inside = has & (before < n - 1)
    bracketed = inside & (grid - stamps[prev] <= tolerance_ns) & (stamps[nxt] - grid <= tolerance_ns)
    associated = exact | bracketed
    if not associated.any():
        raise RecordingError(
            f"{series.name}: no step of the truth's grid lies within {tolerance_s:.6g} s of the estimate's stamps "
            f"(truth {grid[0] / 1e9:.9f} .. {grid[-1] / 1e9:.9f} s, estimate {stamps[0] / 1e9:.9f} .. "
            f"{stamps[-1] / 1e9:.9f} s): are they on the same clock?"
        )
    at = np.where(associated, grid, stamps[prev])[has]  # where each estimated step is evaluated (held: the latest stamp)
    states = np.tile(_PRIOR, (len(grid), 1))
    states[has, :7] = resample_truth(stamps, series.poses, at)[0]
    states[has, 7:] = _resample_linear(np.asarray(series.twist_stamps_ns, dtype=np.int64), series.twists, at)
    covariances = None
    if series.covariances is not None:
        covariances = np.zeros((len(grid), 6, 6))
        covariances[has] = _resample_linear(stamps, series.covariances.reshape(n, 36), at).reshape(-1, 6, 6)
    return AssociatedEstimate(
        name=series.name, source=series.source, twist_source=series.twist_source, states=states, initialised=has,
        associated=associated, covariances=covariances, tolerance_s=float(tolerance_s),
        digest=_digest(np.frombuffer(series.digest.encode(), dtype=np.uint8), grid, np.array([tolerance_s])),
    )


def align_se3(estimate: AssociatedEstimate, truth: Float[ArrayF, "T 13"]) -> AssociatedEstimate:
    """``estimate`` rigidly aligned to ``truth`` over its associated steps (module docstring).

    Raises:
        RecordingError: the alignment is not determined (non-finite values).
    """
    truth = np.asarray(truth, dtype=np.float64)
    mask = estimate.associated
    true_positions, positions = truth[mask, 4:7], estimate.states[mask, 4:7]
    centred = true_positions - true_positions.mean(axis=0)
    spread = np.linalg.svd(centred, compute_uv=False)[1] / np.sqrt(len(centred)) if len(centred) >= 3 else 0.0
    try:
        if spread >= MIN_PLANAR_SPREAD:
            transform = umeyama(positions, true_positions)
        else:
            transform = attitude_alignment(positions, true_positions, quat.rotation_matrix(estimate.states[mask, :4]),
                                           quat.rotation_matrix(truth[mask, :4]))
    except ValueError as exc:
        raise RecordingError(f"{estimate.name}: cannot align (SE(3)) to the truth over its {int(mask.sum())} "
                             f"associated steps: {exc}") from None
    rotation, q = transform.rotation, transform.quaternion
    has = estimate.initialised
    states = estimate.states.copy()
    states[has, :4] = quat.multiply(np.broadcast_to(q, (int(has.sum()), 4)), states[has, :4])
    states[has, 4:7] = transform.apply(states[has, 4:7])
    states[has, 7:10] = states[has, 7:10] @ rotation.T
    states[has, 10:13] = states[has, 10:13] @ rotation.T
    covariances = estimate.covariances
    if covariances is not None:
        block = np.kron(np.eye(2), rotation)
        covariances = covariances.copy()
        covariances[has] = symmetrize(block @ covariances[has] @ block.T)
    return replace(estimate, states=states, covariances=covariances, alignment=transform,
                   digest=_digest(np.frombuffer(estimate.digest.encode(), dtype=np.uint8), rotation,
                                  transform.translation))
