"""What every recording reader shares: errors, topic descriptions, the validated series of a
topic, and the checks and repairs of a topic's messages (:class:`Recording`), written once for
all file formats (MCAP: :mod:`~fkn_bench.recordings.reader`; ROS 1 and ROS 2 bags:
:mod:`~fkn_bench.recordings.bags`).

Supported messages (by type name and message encoding; :mod:`~fkn_bench.recordings.codecs`
decodes them):

* ROS 2 (``cdr``) and ROS 1 (``ros1``): ``geometry_msgs/PoseStamped``,
  ``geometry_msgs/PoseWithCovarianceStamped``, ``nav_msgs/Odometry`` (poses, and Odometry's
  twist) and ``geometry_msgs/TwistStamped`` (twists); ``geometry_msgs/msg/X`` and
  ``geometry_msgs/X`` name the same type.
* ``json``: ``foxglove.PoseInFrame``.

Messages of a topic are taken in log-time order (the time the recorder received them; ties in
file order); "message #i" in errors and reports counts from 0 in that order. Time stamps are the
message's own (``header.stamp``, ``timestamp`` for Foxglove); with ``time_source="auto"`` a topic
whose stamps are all zero (an unset header, as some simulators publish) uses the log time
instead, and says so.

Problems of a topic's messages, and what ``repair=True`` does about them (without it, each raises
:class:`RecordingError` naming the file, the topic and the message):

* undecodable message, non-finite values, implausible values (a position beyond +-1e6 m, a
  rate beyond +-1e3 rad/s or m/s: :mod:`fkn_bench.recordings.plausibility`), zero quaternion,
  zero stamp among non-zero ones: drop the message;
* quaternion norm off 1 by more than ``quaternion_tolerance`` (default 1e-6): renormalise it;
* header stamps going backwards: sort the messages by stamp (stable);
* duplicate header stamps: keep the first message of each stamp.

Every repair is listed in the result's ``repairs`` (and issued as a
:class:`RecordingRepairWarning` by the replay functions). Unknown encodings or types and missing
topics (the message lists the topics and types found) are always errors.

**Pose covariances.** ``PoseWithCovarianceStamped`` and ``Odometry`` carry the 6x6 covariance
of the pose, row-major, in ROS's order ``(x, y, z, rotation about x, about y, about z)``: the
position and a small-angle rotation about the fixed axes of the message's ``header.frame_id``
(ROS ``geometry_msgs/PoseWithCovariance``; axes per REP 103). fkn-bench's error state is
``[dtheta(3), dr(3)]``: the world-frame attitude error ``q_true = exp(dtheta/2) (x) q``
(Hamilton, ``q`` body-to-world) and the world-frame position error ``dr = r_true - r``. A
rotation about the fixed axes of the header frame is a left (world-frame) perturbation, so with
the header frame as fkn-bench's world frame the two coincide up to order:
``P_fkn = C[p][:, p]`` with ``p = [3, 4, 5, 0, 1, 2]`` (no rotation). (A producer that reports
the attitude block in the body frame, ``q_true = q (x) exp(dphi/2)``, has
``dtheta = R(q) dphi``; such covariances must be rotated by ``R(q)`` before they are recorded.)
A covariance that is not finite, not symmetric (``|C - C^T| <= 1e-9 max|C|``) or not positive
definite (ROS's all-zero "unknown" included) is NaN in :attr:`PoseSeries.covariances` for that
message, and a note counts them; valid ones are symmetrised (``(C + C^T) / 2``).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fkn_bench.geometry.quaternion import xyzw_to_wxyz
from fkn_bench.recordings.codecs import DecodeError, decode_stamped
from fkn_bench.recordings.plausibility import component_limits, first_implausible
from fkn_bench.recordings.schemas import canonical_type_name
from fkn_bench.types import STATE_NAMES
from fkn_bench.wording import option, option_name

__all__ = [
    "RecordingError", "TopicNotFoundError", "RecordingRepairWarning", "TopicInfo", "PoseSeries",
    "TwistSeries", "Recording", "POSE_TYPES", "TWIST_TYPES", "ROS_TO_FKN_COVARIANCE_ORDER",
    "pose_covariances", "checked_covariances"
]

_NS = 1_000_000_000

POSE_TYPES: tuple[str, ...] = (
    "geometry_msgs/PoseStamped",
    "geometry_msgs/PoseWithCovarianceStamped",
    "nav_msgs/Odometry",
    "foxglove.PoseInFrame",
)
"""Canonical names of the types a pose topic may have."""
TWIST_TYPES: tuple[str, ...] = ("geometry_msgs/TwistStamped", "nav_msgs/Odometry")
"""Canonical names of the types a twist topic may have."""
_COVARIANCE_TYPES = ("geometry_msgs/PoseWithCovarianceStamped", "nav_msgs/Odometry")

_ODOMETRY = "nav_msgs/Odometry"
_ENCODINGS = {"cdr": "ROS 2 CDR", "ros1": "ROS 1", "json": "JSON"}

ROS_TO_FKN_COVARIANCE_ORDER: tuple[int, ...] = (3, 4, 5, 0, 1, 2)
"""Indices into ROS's pose-covariance order ``(x, y, z, rot x, rot y, rot z)`` giving fkn-bench's
``[dtheta(3), dr(3)]`` (module docstring)."""
_SYMMETRY_TOLERANCE = 1e-9


class RecordingError(ValueError):
    """A recording that cannot be used as asked; the message names the file (and the topic and
    message where one is at fault) and how to proceed."""

    def __init__(self, message: str, *, path: Path | None = None, topic: str | None = None, index: int | None = None):
        super().__init__(message)
        self.path = path
        self.topic = topic
        self.index = index


class TopicNotFoundError(RecordingError):
    """A requested topic is absent; the message lists the topics and types found."""


class RecordingRepairWarning(UserWarning):
    """A documented repair was applied to a recording (see :mod:`fkn_bench.recordings.base`)."""


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a recording."""

    topic: str
    schema_name: str
    schema_encoding: str
    message_encoding: str
    message_count: int | None
    """Messages on the topic (None when the file has no statistics record)."""

    @property
    def type_name(self) -> str:
        """Canonical type name (``geometry_msgs/PoseStamped``)."""
        return canonical_type_name(self.schema_name)

    def describe(self) -> str:
        count = "?" if self.message_count is None else self.message_count
        return f"{self.topic}  {self.schema_name or '(no schema)'} ({self.message_encoding}, {count} messages)"


@dataclass(frozen=True, eq=False, kw_only=True)
class _Series:
    """What every validated series of one topic has (see :class:`PoseSeries`)."""

    topic: str
    type_name: str
    encoding: str
    stamps_ns: np.ndarray
    frame_id: str
    indices: np.ndarray
    time_source: str
    repairs: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()


@dataclass(frozen=True, eq=False, kw_only=True)
class PoseSeries(_Series):
    """Validated poses of one topic, sorted by stamp.

    Attributes:
        topic, type_name, encoding: where they came from.
        stamps_ns: ``(N,)`` int64 stamps (ns), strictly increasing.
        poses: ``(N, 7)`` ``[qw, qx, qy, qz, rx, ry, rz]`` (converted from ROS x, y, z, w).
        frame_id, child_frame_id: of the first message (child only for Odometry).
        twists: ``(N, 6)`` Odometry twist ``[angular(3), linear(3)]`` in ``child_frame_id``, or None.
        covariances: ``(N, 6, 6)`` pose covariances of ``PoseWithCovarianceStamped`` and
            ``Odometry`` messages in fkn-bench's error order ``[dtheta(3), dr(3)]`` (rad^2, m^2,
            rad m), NaN for a message whose covariance is invalid (module docstring); None for
            types without one.
        indices: ``(N,)`` message numbers (log-time order) the rows come from.
        time_source: ``"header"`` or ``"log"``.
        repairs, notes: what was repaired, and other remarks.
    """

    poses: np.ndarray
    child_frame_id: str
    twists: np.ndarray | None
    covariances: np.ndarray | None = None


@dataclass(frozen=True, eq=False, kw_only=True)
class TwistSeries(_Series):
    """Validated twists of one topic: ``twists (N, 6)`` = ``[angular(3), linear(3)]`` in
    ``frame_id``; other attributes as :class:`PoseSeries`."""

    twists: np.ndarray



def describe_exception(exc: BaseException) -> str:
    text = str(exc).strip()
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _seconds(ns: int) -> str:
    return f"{ns / _NS:.9f} s"


def pose_covariances(ros: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """fkn-bench pose covariances of ROS ones (module docstring).

    Args:
        ros: ``(N, 36)`` row-major ROS covariances, order ``(x, y, z, rot x, rot y, rot z)``.

    Returns:
        ``(covariances (N, 6, 6), valid (N,))``: reordered to ``[dtheta(3), dr(3)]`` and
        :func:`checked_covariances`.
    """
    order = list(ROS_TO_FKN_COVARIANCE_ORDER)
    return checked_covariances(np.asarray(ros, dtype=np.float64).reshape(-1, 6, 6)[:, order][:, :, order])


def checked_covariances(covariances: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(symmetrised (..., n, n), valid (...))`` of stated covariances ``(..., n, n)``: valid
    where finite, symmetric to ``1e-9`` of the largest entry and positive definite (symmetrised
    there), NaN elsewhere."""
    c = np.asarray(covariances, dtype=np.float64)
    finite = np.isfinite(c).all(axis=(-2, -1))
    c = np.where(finite[..., None, None], c, 0.0)
    transposed = np.swapaxes(c, -1, -2)
    scale = np.abs(c).max(axis=(-2, -1), initial=0.0)
    valid = finite & (scale > 0) & (np.abs(c - transposed).max(axis=(-2, -1), initial=0.0) <= _SYMMETRY_TOLERANCE * scale)
    symmetric = 0.5 * (c + transposed)
    if valid.any():
        valid[valid] = np.linalg.eigvalsh(symmetric[valid])[..., 0] > 0
    return np.where(valid[..., None, None], symmetric, np.nan), valid


class Recording:
    """A recording opened for reading pose and twist topics: the interface every reader has, and
    the checks and repairs of a topic's messages (module docstring), shared by all formats.

    A subclass sets ``path`` and ``repair`` (by calling this ``__init__``) and provides
    :meth:`topics`, :meth:`metadata`, :meth:`prefetch` and :meth:`_payloads`.

    Attributes:
        path: the recording.
        repair: apply the documented repairs instead of raising.
        repairs, notes: repairs applied to the file as a whole, and other remarks.
    """

    def __init__(self, path: str | Path, *, repair: bool = False) -> None:
        self.path = Path(path)
        self.repair = bool(repair)
        self.repairs: list[str] = []
        self.notes: list[str] = []

    # ------------------------------------------------------------------ what a format provides
    def topics(self) -> dict[str, TopicInfo]:
        """Topics with their types, encodings and message counts, by topic name."""
        raise NotImplementedError

    def metadata(self) -> dict[str, dict[str, str]]:
        """Metadata records ``{name: {key: value}}`` of the file (empty if the format has none)."""
        raise NotImplementedError

    def prefetch(self, topics: Iterable[str]) -> None:
        """Read the raw messages of several topics in one pass over the file (cached)."""
        raise NotImplementedError

    def _payloads(self, topic: str) -> list[tuple[int, bytes]]:
        """``(log_time_ns, serialised message)`` of ``topic`` in log-time order (ties in file order)."""
        raise NotImplementedError

    # ------------------------------------------------------------------ shared

    def _error(self, message: str, **where: Any) -> RecordingError:
        return RecordingError(f"{self.path}: {message}", path=self.path, **where)

    def _repair(self, error: str, note: str, repairs: list[str] | None = None, **where: Any) -> None:
        """Raise ``error`` (which says how to repair) unless repairing; else record ``note`` in
        ``repairs`` (default: the file's)."""
        if not self.repair:
            raise self._error(error, **where)
        (self.repairs if repairs is None else repairs).append(note)

    def describe_topics(self) -> str:
        topics = self.topics()
        if not topics:
            return "the recording has no topics"
        width = max(len(t) for t in topics)
        lines = [f"  {info.topic:<{width}}  {info.describe()[len(info.topic) + 2:]}" for info in topics.values()]
        return "topics in this recording:\n" + "\n".join(lines)

    def require_topic(self, topic: str, role: str) -> TopicInfo:
        """Info of ``topic`` or :class:`TopicNotFoundError` listing the topics found."""
        topics = self.topics()
        if topic not in topics:
            raise TopicNotFoundError(
                f"{self.path}: {role} topic {topic!r} not found; {self.describe_topics()}", path=self.path, topic=topic
            )
        info = topics[topic]
        if info.message_count == 0:
            raise self._error(f"{role} topic {topic!r} has no messages", topic=topic)
        return info

    def _series(
        self, topic: str, role: str, allowed: tuple[str, ...], time_source: str, with_poses: bool,
        quaternion_tolerance: float = 1e-6,
    ) -> dict[str, Any]:
        """The fields of a :class:`PoseSeries` of ``topic`` (``poses`` None unless ``with_poses``,
        ``twists`` None unless the type has a twist): the messages that pass the checks of the
        module docstring (or are repaired), in stamp order."""
        info = self.require_topic(topic, role)
        type_name, encoding = info.type_name, info.message_encoding
        schema = info.schema_name or type_name
        if encoding not in _ENCODINGS:
            raise self._error(
                f"{role} topic {topic!r} uses message encoding {encoding!r} (schema {info.schema_name!r}, schema "
                f"encoding {info.schema_encoding!r}); fkn-bench reads 'cdr' (ROS 2), 'ros1' (ROS 1) and 'json' "
                "(foxglove.PoseInFrame)",
                topic=topic,
            )
        if type_name not in allowed or (encoding == "json") != (type_name == "foxglove.PoseInFrame"):
            raise self._error(
                f"{role} topic {topic!r} has type {info.schema_name or '(no schema)'!r} ({encoding}); a {role} topic "
                f"must be one of {', '.join(allowed)} (JSON only for foxglove.PoseInFrame)",
                topic=topic,
            )
        repairs: list[str] = []
        notes: list[str] = []

        def refuse(i: int, error: str, note: str) -> None:
            """Raise ``error`` about message #i unless repairing; else record ``note``."""
            self._repair(f"{role} topic {topic!r}: message #{i} {error}", f"{topic}: {note}", repairs,
                         topic=topic, index=i)

        # decode, in log-time order
        rows: list[tuple[int, int, int, str, str, tuple[float, ...]]] = []
        dropped: list[tuple[int, int, BaseException]] = []
        for i, (log_time, data) in enumerate(self._payloads(topic)):
            try:
                stamp, frame, child, values = decode_stamped(type_name, encoding, data)
            except DecodeError as exc:
                dropped.append((i, log_time, exc))
                continue
            rows.append((i, log_time, stamp, frame, child, values))
        if dropped:
            i, log_time, exc = dropped[0]
            refuse(
                i,
                f"(log time {_seconds(log_time)}) cannot be decoded as {schema} ({_ENCODINGS[encoding]}): "
                f"{exc}. Pass {option('repair')} to drop undecodable messages",
                f"dropped {len(dropped)} undecodable message(s) (first: #{i})",
            )
        if not rows:
            raise self._error(f"{role} topic {topic!r} has no decodable messages", topic=topic)
        numbers, log, header, frames, children, columns = zip(*rows)
        indices = np.array(numbers, dtype=np.int64)
        values = np.array(columns, dtype=np.float64)
        keep = np.ones(len(indices), dtype=bool)

        # time stamps
        if time_source not in ("auto", "header", "log"):
            raise ValueError(f"time_source must be 'auto', 'header' or 'log' (got {time_source!r})")
        zero = np.array(header) == 0
        if time_source == "log" or (time_source == "auto" and zero.all()):
            if time_source == "auto":
                notes.append(f"{topic}: every header stamp is zero; used the log times (receive times) instead")
            stamps, source = np.array(log, dtype=np.int64), "log"
        elif zero.all():
            raise self._error(
                f"{role} topic {topic!r}: every header stamp is zero; use {option('time_source', 'log')} (or 'auto')",
                topic=topic, index=int(indices[0]),
            )
        else:
            if zero.any():
                first = int(indices[np.argmax(zero)])
                refuse(
                    first,
                    "has a zero header stamp while others do not. "
                    f"Pass {option('repair')} to drop such messages, or {option('time_source', 'log')}",
                    f"dropped {int(zero.sum())} message(s) with a zero header stamp (first: #{first})",
                )
                keep &= ~zero
            stamps, source = np.array(header, dtype=np.int64), "header"

        # values: ROS order position(3), orientation xyzw(4) [, pose cov(36)] [, twist linear(3) angular(3)]
        poses = twists = None
        if with_poses:
            poses = np.concatenate([xyzw_to_wxyz(values[:, 3:7]), values[:, 0:3]], axis=1)
        if type_name in TWIST_TYPES:
            linear = 43 if type_name == _ODOMETRY else 0
            twists = np.concatenate([values[:, linear + 3 : linear + 6], values[:, linear : linear + 3]], axis=1)
        checked = np.concatenate([a for a in (poses, twists) if a is not None], axis=1)
        names = (STATE_NAMES[:7] if poses is not None else ()) + (STATE_NAMES[7:] if twists is not None else ())
        ok = np.isfinite(checked).all(axis=1)
        zero_q = np.zeros_like(ok)
        if poses is not None:
            zero_q = ok & (np.linalg.norm(np.nan_to_num(poses[:, :4]), axis=1) < 1e-9)
        ok &= ~zero_q
        beyond = ok.copy()
        with np.errstate(invalid="ignore"):
            beyond[ok] = np.any(np.abs(checked[ok]) > component_limits(names), axis=1)
        ok &= ~beyond
        bad = keep & ~ok
        if bad.any():
            i = int(np.argmax(bad))
            what = ("a zero quaternion" if zero_q[i] else
                    f"an implausible value ({first_implausible(checked[i], names, quaternion_tolerance=None)[1]})"
                    if beyond[i] else "a non-finite value (NaN or infinity)")
            refuse(
                int(indices[i]),
                f"has {what}; pass {option('repair')} to drop such messages",
                f"dropped {int(bad.sum())} message(s) with non-finite or implausible values or zero quaternions "
                f"(first: #{int(indices[i])})",
            )
        keep &= ok
        if poses is not None:
            norms = np.linalg.norm(poses[:, :4], axis=1)
            bad_norm = keep & (np.abs(norms - 1.0) > quaternion_tolerance)
            if bad_norm.any():
                i = int(np.argmax(bad_norm))
                refuse(
                    int(indices[i]),
                    f"has a quaternion of norm {norms[i]:.9g}, not 1 (tolerance {quaternion_tolerance:g}); pass "
                    f"{option('repair')} to renormalise such quaternions, or a larger {option_name('quaternion_tolerance')}",
                    f"renormalised {int(bad_norm.sum())} quaternion(s) with a norm off 1 by more than "
                    f"{quaternion_tolerance:g} (first: #{int(indices[i])}, norm {norms[i]:.9g})",
                )
                poses[bad_norm, :4] /= norms[bad_norm, None]

        # order: sort by stamp, drop duplicate stamps
        rows_kept = np.flatnonzero(keep)
        kept_stamps, kept_indices = stamps[rows_kept], indices[rows_kept]
        order = np.arange(len(rows_kept))
        back = np.flatnonzero(np.diff(kept_stamps) < 0) + 1
        if len(back):
            i = int(back[0])
            refuse(
                int(kept_indices[i]),
                f"has stamp {_seconds(int(kept_stamps[i]))}, earlier than message #{int(kept_indices[i - 1])} "
                f"({_seconds(int(kept_stamps[i - 1]))}): the time stamps are not monotonic. Pass {option('repair')} to "
                "sort the messages by stamp",
                f"sorted the messages by stamp ({len(back)} went backwards; first: #{int(kept_indices[i])})",
            )
            order = np.argsort(kept_stamps, kind="stable")
        same = np.flatnonzero(np.diff(kept_stamps[order]) == 0) + 1
        if len(same):
            i = int(same[0])
            this, before = int(kept_indices[order[i]]), int(kept_indices[order[i - 1]])
            refuse(
                this,
                f"has the same stamp {_seconds(int(kept_stamps[order[i]]))} as message #{before} (duplicate time "
                f"stamps). Pass {option('repair')} to keep only the first message of each stamp",
                f"dropped {len(same)} message(s) with a duplicate stamp, keeping the first of each "
                f"(first dropped: #{this})",
            )
            order = np.delete(order, same)
        order = rows_kept[order]
        if len(order) == 0:
            raise self._error(f"{role} topic {topic!r} has no usable messages", topic=topic)
        covariances = None
        if with_poses and type_name in _COVARIANCE_TYPES:
            covariances, valid = pose_covariances(values[order, 7:43])
            if not valid.all():
                first = int(indices[order][np.argmin(valid)])
                notes.append(
                    f"{topic}: {int((~valid).sum())} of {len(valid)} pose covariance(s) are not finite, symmetric and "
                    f"positive definite (first: #{first}); kept as NaN"
                )
        return dict(
            topic=topic, covariances=covariances, type_name=type_name, encoding=encoding, stamps_ns=stamps[order], indices=indices[order],
            time_source=source, repairs=tuple(repairs), notes=tuple(notes), frame_id=frames[0],
            child_frame_id=children[0], poses=None if poses is None else poses[order],
            twists=None if twists is None else twists[order],
        )

    def read_poses(
        self, topic: str, *, role: str = "pose", time_source: str = "auto", quaternion_tolerance: float = 1e-6
    ) -> PoseSeries:
        """Validated poses of ``topic`` (see module docstring for the checks and repairs)."""
        return PoseSeries(**self._series(topic, role, POSE_TYPES, time_source, True, quaternion_tolerance))

    def read_twists(self, topic: str, *, role: str = "twist", time_source: str = "auto") -> TwistSeries:
        """Validated twists of ``topic`` (``TwistStamped``, or the twist part of ``Odometry``)."""
        fields = self._series(topic, role, TWIST_TYPES, time_source, False)
        del fields["poses"], fields["covariances"]
        child_frame_id = fields.pop("child_frame_id")
        if fields["type_name"] == _ODOMETRY:
            fields["frame_id"] = child_frame_id
        return TwistSeries(**fields)

