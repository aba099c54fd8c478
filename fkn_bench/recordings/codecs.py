"""Serialisation of the few message types fkn-bench writes and reads.

Three wire formats:

* ROS 2 CDR (message encoding ``cdr``): written by ``mcap-ros2-support`` (:func:`encode_ros2`,
  from the schema texts of :mod:`~fkn_bench.recordings.schemas`), read by ``rosbags``' typestore
  of the standard ROS 2 (Humble) messages (:func:`decode_stamped`).
* ROS 1 (message encoding ``ros1``, read only): read by ``rosbags``' typestore of the standard
  ROS 1 (Noetic) messages, whose ``std_msgs/Header`` has ``seq``.
* JSON ``foxglove.PoseInFrame`` (message encoding ``json``), written and read here.

Every supported ROS type is a header, optionally a second string (``nav_msgs/Odometry``'s
``child_frame_id``) and ``float64`` fields; :data:`LAYOUTS` lists those fkn-bench writes in ROS
order (positions ``x y z``, quaternions ``x y z w``, twists ``linear`` then ``angular``).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from mcap_ros2._dynamic import serialize_dynamic
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from fkn_bench.recordings.schemas import canonical_type_name, ros2_schema_text
from fkn_bench.types import ArrayF

__all__ = [
    "LAYOUTS", "Layout", "DecodeError", "split_stamp", "encode_ros2", "decode_stamped",
    "encode_pose_in_frame", "decode_pose_in_frame"
]

_NS = 1_000_000_000


class DecodeError(ValueError):
    """A message whose bytes do not match its declared type (the message names the field)."""


@dataclass(frozen=True)
class Layout:
    """Wire layout of a stamped ROS message: header, optional second string (``child_frame``) and
    ``n_doubles`` float64 fields in ROS order; ``body`` makes the message below the header from
    those fields and the child frame (for :func:`encode_ros2`)."""

    name: str
    child_frame: bool
    n_doubles: int
    body: Callable[[list[float], str], dict]


def _pose(v: list[float]) -> dict:
    return {"position": dict(zip("xyz", v[0:3])), "orientation": dict(zip("xyzw", v[3:7]))}


def _twist(v: list[float]) -> dict:
    return {"linear": dict(zip("xyz", v[0:3])), "angular": dict(zip("xyz", v[3:6]))}


LAYOUTS: dict[str, Layout] = {
    layout.name: layout
    for layout in (
        # position(3), orientation xyzw(4)
        Layout("geometry_msgs/PoseStamped", False, 7, lambda v, child: {"pose": _pose(v)}),
        # linear(3), angular(3)
        Layout("geometry_msgs/TwistStamped", False, 6, lambda v, child: {"twist": _twist(v)}),
        Layout("geometry_msgs/PoseWithCovarianceStamped", False, 7 + 36,
               lambda v, child: {"pose": {"pose": _pose(v), "covariance": v[7:43]}}),
        # pose(7), pose covariance(36), twist linear(3) angular(3), twist covariance(36)
        Layout("nav_msgs/Odometry", True, 7 + 36 + 6 + 36, lambda v, child: {
            "child_frame_id": child,
            "pose": {"pose": _pose(v), "covariance": v[7:43]},
            "twist": {"twist": _twist(v[43:49]), "covariance": v[49:85]},
        }),
    )
}
"""Canonical ROS type name (``package/Type``) -> :class:`Layout`."""


def split_stamp(stamps_ns: ArrayF) -> tuple[np.ndarray, np.ndarray]:
    """Seconds and nanoseconds of integer nanosecond stamps; raises ``ValueError`` outside the
    ROS 2 ``builtin_interfaces/Time`` range (``int32`` seconds, not negative)."""
    ns = np.asarray(stamps_ns, dtype=np.int64)
    sec, nsec = np.divmod(ns, _NS)
    if ns.size and (sec.min() < 0 or sec.max() > 2**31 - 1):
        raise ValueError(f"time stamps must lie in [0, {2**31 - 1}] s")
    return sec, nsec


@lru_cache(maxsize=None)
def _ros2_encoder(type_name: str) -> Callable[[Any], bytes]:
    name = "/msg/".join(type_name.split("/"))
    return serialize_dynamic(name, ros2_schema_text(type_name))[name]


def encode_ros2(
    type_name: str, stamps_ns: np.ndarray, values: ArrayF, frame_id: str, *, child_frame_id: str = ""
) -> list[bytes]:
    """ROS 2 CDR bytes of ``N`` messages of a type in :data:`LAYOUTS`, serialised by
    ``mcap-ros2-support`` from the schema text of :func:`~fkn_bench.recordings.schemas.ros2_schema_text`.

    Args:
        type_name: ROS type (``geometry_msgs/msg/PoseStamped`` or ``geometry_msgs/PoseStamped``).
        stamps_ns: ``(N,)`` integer header stamps, ns.
        values: ``(N, n_doubles)`` float64 fields in ROS order.
        frame_id, child_frame_id: header frame (and Odometry's child frame) of every message.
    """
    name = canonical_type_name(type_name)
    values = np.asarray(values, dtype=np.float64)
    if values.shape != (len(stamps_ns), LAYOUTS[name].n_doubles):
        raise ValueError(f"values must have shape ({len(stamps_ns)}, {LAYOUTS[name].n_doubles}) (got {values.shape})")
    sec, nsec = split_stamp(stamps_ns)
    encode, body = _ros2_encoder(name), LAYOUTS[name].body
    return [
        encode({"header": {"stamp": {"sec": s, "nanosec": ns}, "frame_id": frame_id}, **body(v, child_frame_id)})
        for s, ns, v in zip(sec.tolist(), nsec.tolist(), values.tolist())
    ]


@lru_cache(maxsize=None)
def _typestore(encoding: str) -> Typestore:
    """rosbags' typestore of the standard messages of ``encoding``: ROS 1 Noetic for ``ros1``
    (``std_msgs/Header`` with ``seq``), ROS 2 Humble for ``cdr``."""
    return get_typestore(Stores.ROS1_NOETIC if encoding == "ros1" else Stores.ROS2_HUMBLE)


def _xyz(v: Any) -> tuple[float, float, float]:
    return (v.x, v.y, v.z)


def _pose_fields(p: Any) -> tuple[float, ...]:
    return (*_xyz(p.position), *_xyz(p.orientation), p.orientation.w)


def _twist_fields(t: Any) -> tuple[float, ...]:
    return (*_xyz(t.linear), *_xyz(t.angular))


_FIELDS: dict[str, Callable[[Any], tuple[float, ...]]] = {
    "geometry_msgs/PoseStamped": lambda m: _pose_fields(m.pose),
    "geometry_msgs/TwistStamped": lambda m: _twist_fields(m.twist),
    "geometry_msgs/PoseWithCovarianceStamped": lambda m: (*_pose_fields(m.pose.pose), *m.pose.covariance.tolist()),
    "nav_msgs/Odometry": lambda m: (
        *_pose_fields(m.pose.pose), *m.pose.covariance.tolist(), *_twist_fields(m.twist.twist)
    ),
}
"""Canonical type name -> the float64 fields :func:`decode_stamped` returns, in ROS order: pose
(position, quaternion xyzw), its covariance (36, row-major), twist (linear, angular)."""


def decode_stamped(type_name: str, encoding: str, data: bytes) -> tuple[int, str, str, tuple[float, ...]]:
    """Parse one ``PoseStamped``, ``PoseWithCovarianceStamped``, ``Odometry`` or
    ``TwistStamped`` (ROS 2 CDR or ROS 1, deserialised by rosbags' typestore of the standard
    messages), or (``encoding="json"``) a ``foxglove.PoseInFrame`` (:func:`decode_pose_in_frame`).

    Returns:
        ``(stamp_ns, frame_id, child_frame_id, values)``; ``values`` are the type's float64 fields
        in ROS order (:data:`_FIELDS`: ``PoseStamped`` 7, ``PoseWithCovarianceStamped`` 43,
        ``Odometry`` 49 (its twist covariance is not read), ``TwistStamped`` 6);
        ``child_frame_id`` is ``""`` for types without one.

    Raises:
        DecodeError: with rosbags' account of what could not be read.
    """
    if encoding == "json":
        stamp, frame_id, values = decode_pose_in_frame(data)
        return stamp, frame_id, "", values
    name = canonical_type_name(type_name)
    if encoding == "ros1":
        deserialize = _typestore(encoding).deserialize_ros1
    elif encoding == "cdr":
        deserialize = _typestore(encoding).deserialize_cdr
    else:
        raise DecodeError(f"unknown message encoding {encoding!r}")
    try:
        message = deserialize(data, name.replace("/", "/msg/"))
    except Exception as exc:  # SerdeError, and whatever a malformed buffer makes the generated code raise
        raise DecodeError(str(exc).strip() or type(exc).__name__) from None
    stamp = message.header.stamp
    return (
        stamp.sec * _NS + stamp.nanosec, message.header.frame_id, getattr(message, "child_frame_id", ""),
        _FIELDS[name](message),
    )


def encode_pose_in_frame(stamps_ns: np.ndarray, frame_id: str, values: ArrayF) -> list[bytes]:
    """JSON ``foxglove.PoseInFrame`` messages; ``values (N, 7)`` = position xyz, orientation xyzw.

    Floats are written with Python's shortest round-trip representation, so a JSON reader gets the
    same float64 back; non-finite values become ``null``.
    """
    sec, nsec = split_stamp(stamps_ns)
    values = np.asarray(values, dtype=np.float64)
    rows = np.where(np.isfinite(values), values, np.nan).tolist()
    return [
        json.dumps(
            {"timestamp": {"sec": s, "nsec": ns}, "frame_id": frame_id, "pose": _pose([None if v != v else v for v in row])},
            separators=(",", ":"),
        ).encode()
        for s, ns, row in zip(sec.tolist(), nsec.tolist(), rows)
    ]


def _number(value: object, where: str) -> float:
    if value is None:
        return float("nan")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise DecodeError(f"{where} must be a number (got {value!r})")
    return float(value)


def decode_pose_in_frame(data: bytes) -> tuple[int, str, tuple[float, ...]]:
    """Parse a JSON ``foxglove.PoseInFrame``: ``(stamp_ns, frame_id, (px, py, pz, qx, qy, qz, qw))``."""
    try:
        document = json.loads(data)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DecodeError(f"not valid JSON ({exc})") from None
    try:
        stamp = document["timestamp"]
        sec, nsec = stamp["sec"], stamp["nsec"]
        position = document["pose"]["position"]
        orientation = document["pose"]["orientation"]
        frame_id = document.get("frame_id", "")
        values: Sequence[float] = tuple(
            [_number(position[k], f"pose.position.{k}") for k in "xyz"]
            + [_number(orientation[k], f"pose.orientation.{k}") for k in "xyzw"]
        )
    except (KeyError, TypeError, AttributeError) as exc:
        raise DecodeError(f"not a foxglove.PoseInFrame document (missing or malformed field {exc})") from None
    if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in (sec, nsec)):
        raise DecodeError(f"timestamp must hold non-negative integers sec and nsec (got {stamp!r})")
    return int(sec) * _NS + int(nsec), str(frame_id), tuple(values)
