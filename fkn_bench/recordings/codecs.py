"""Serialisation of the few message types fkn-bench writes and reads, vectorised over messages.

Three wire formats:

* ROS 2 CDR (MCAP message encoding ``cdr``): a 4-byte encapsulation header (``00 01 00 00``,
  little-endian plain CDR; ``00 00`` big-endian is also read), then the fields, each aligned to
  its own size counted from the end of the encapsulation header; ``builtin_interfaces/Time`` is
  ``int32 sec, uint32 nanosec``; a string is a ``uint32`` length that counts a terminating NUL,
  the bytes and the NUL. The encoder's bytes are tested to be identical to those of
  ``mcap-ros2-support``'s encoder.
* ROS 1 (message encoding ``ros1``): little-endian, no alignment, ``std_msgs/Header`` is
  ``uint32 seq, time stamp (uint32 secs, uint32 nsecs), string frame_id``; a string is a
  ``uint32`` length and the bytes, without NUL.
* JSON ``foxglove.PoseInFrame`` (message encoding ``json``).

Every supported ROS type is a header, optionally a second string (``nav_msgs/Odometry``'s
``child_frame_id``) and a run of ``float64`` fields; :data:`LAYOUTS` lists them in ROS order
(positions ``x y z``, quaternions ``x y z w``, twists ``linear`` then ``angular``).
"""

from __future__ import annotations

import json
import struct
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fkn_bench.recordings.schemas import canonical_type_name
from fkn_bench.types import ArrayF

__all__ = [
    "LAYOUTS",
    "Layout",
    "DecodeError",
    "CDR_LE_HEADER",
    "split_stamp",
    "encode_stamped",
    "decode_stamped",
    "encode_pose_in_frame",
    "decode_pose_in_frame",
]

CDR_LE_HEADER = b"\x00\x01\x00\x00"
_NS = 1_000_000_000


class DecodeError(ValueError):
    """A message whose bytes do not match its declared type (the message names the field)."""


@dataclass(frozen=True)
class Layout:
    """Wire layout of a stamped ROS message: header, optional second string, ``n_doubles``."""

    name: str
    child_frame: bool
    n_doubles: int


LAYOUTS: dict[str, Layout] = {
    layout.name: layout
    for layout in (
        Layout("geometry_msgs/PoseStamped", False, 7),  # position(3), orientation xyzw(4)
        Layout("geometry_msgs/TwistStamped", False, 6),  # linear(3), angular(3)
        Layout("geometry_msgs/PoseWithCovarianceStamped", False, 7 + 36),
        # pose(7), pose covariance(36), twist linear(3) angular(3), twist covariance(36)
        Layout("nav_msgs/Odometry", True, 7 + 36 + 6 + 36),
    )
}
"""Canonical ROS type name (``package/Type``) -> :class:`Layout`."""


def split_stamp(stamps_ns: ArrayF, encoding: str) -> tuple[np.ndarray, np.ndarray]:
    """Seconds and nanoseconds of integer nanosecond stamps; raises ``ValueError`` out of range
    (ROS 2 ``int32`` seconds, ROS 1 ``uint32``)."""
    ns = np.asarray(stamps_ns, dtype=np.int64)
    sec, nsec = np.divmod(ns, _NS)
    high = 2**31 - 1 if encoding == "cdr" else 2**32 - 1
    if ns.size and (sec.min() < 0 or sec.max() > high):
        raise ValueError(f"time stamps must lie in [0, {high}] s for {encoding} messages")
    return sec, nsec


def _align(offset: int, size: int) -> int:
    """CDR alignment: offsets count from the end of the 4-byte encapsulation header."""
    body = offset - 4
    return 4 + (body + size - 1) // size * size


def _string_bytes(text: str, encoding: str) -> bytes:
    raw = text.encode("utf-8")
    return raw + b"\x00" if encoding == "cdr" else raw


def encode_stamped(
    type_name: str,
    encoding: str,
    stamps_ns: np.ndarray,
    values: ArrayF,
    frame_id: str,
    *,
    child_frame_id: str = "",
    seq: np.ndarray | None = None,
) -> list[bytes]:
    """Serialise ``N`` messages of a type in :data:`LAYOUTS` at once.

    Args:
        type_name: ROS type (``geometry_msgs/msg/PoseStamped`` or ``geometry_msgs/PoseStamped``).
        encoding: ``"cdr"`` (ROS 2) or ``"ros1"``.
        stamps_ns: ``(N,)`` integer header stamps, ns.
        values: ``(N, n_doubles)`` float64 fields in ROS order.
        frame_id, child_frame_id: header frame (and Odometry's child frame) of every message.
        seq: ROS 1 header sequence numbers (default ``0 .. N-1``).

    Returns:
        One ``bytes`` per message.
    """
    layout = LAYOUTS[canonical_type_name(type_name)]
    values = np.asarray(values, dtype=np.float64)
    n = len(stamps_ns)
    if values.shape != (n, layout.n_doubles):
        raise ValueError(f"{layout.name} needs values of shape ({n}, {layout.n_doubles}) (got {values.shape})")
    sec, nsec = split_stamp(stamps_ns, encoding)
    frame = _string_bytes(frame_id, encoding)
    child = _string_bytes(child_frame_id, encoding)
    names: list[str] = []
    formats: list[object] = []
    offsets: list[int] = []

    def field(name: str, fmt: object, offset: int) -> None:
        names.append(name)
        formats.append(fmt)
        offsets.append(offset)

    if encoding == "cdr":
        field("encapsulation", "V4", 0)
        field("sec", "<i4", 4)
        field("nsec", "<u4", 8)
        field("frame_len", "<u4", 12)
        pos = 16
        if frame:
            field("frame", f"V{len(frame)}", pos)
        pos += len(frame)
        if layout.child_frame:
            pos = _align(pos, 4)
            field("child_len", "<u4", pos)
            if child:
                field("child", f"V{len(child)}", pos + 4)
            pos += 4 + len(child)
        pos = _align(pos, 8)
    elif encoding == "ros1":
        field("seq", "<u4", 0)
        field("sec", "<u4", 4)
        field("nsec", "<u4", 8)
        field("frame_len", "<u4", 12)
        pos = 16
        if frame:
            field("frame", f"V{len(frame)}", pos)
        pos += len(frame)
        if layout.child_frame:
            field("child_len", "<u4", pos)
            if child:
                field("child", f"V{len(child)}", pos + 4)
            pos += 4 + len(child)
    else:
        raise ValueError(f"unknown message encoding {encoding!r} (expected 'cdr' or 'ros1')")
    field("values", ("<f8", (layout.n_doubles,)), pos)
    size = pos + 8 * layout.n_doubles
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": size})
    records = np.zeros(n, dtype=dtype)
    if encoding == "cdr":
        records["encapsulation"] = np.void(CDR_LE_HEADER)
    else:
        records["seq"] = np.arange(n) if seq is None else np.asarray(seq)
    records["sec"] = sec
    records["nsec"] = nsec
    records["frame_len"] = len(frame)
    if frame:
        records["frame"] = np.void(frame)
    if layout.child_frame:
        records["child_len"] = len(child)
        if child:
            records["child"] = np.void(child)
    records["values"] = values
    blob = records.tobytes()
    return [blob[i : i + size] for i in range(0, n * size, size)]


def decode_stamped(type_name: str, encoding: str, data: bytes) -> tuple[int, str, str, tuple[float, ...]]:
    """Parse one message of a type in :data:`LAYOUTS`.

    Returns:
        ``(stamp_ns, frame_id, child_frame_id, values)`` with ``values`` the type's float64
        fields in ROS order (``child_frame_id`` is ``""`` for types without one).

    Raises:
        DecodeError: naming the field that could not be read.
    """
    layout = LAYOUTS[canonical_type_name(type_name)]
    size = len(data)
    if encoding == "cdr":
        if size < 4 or data[0] != 0 or data[1] not in (0, 1):
            head = data[:4].hex(" ") if size else "nothing"
            raise DecodeError(
                f"unsupported CDR encapsulation header {head} (expected 00 01 00 00, plain little-endian CDR)"
            )
        order = "<" if data[1] == 1 else ">"
        pos, stamp_fmt, nul = 4, order + "iI", True
    elif encoding == "ros1":
        order, pos, stamp_fmt, nul = "<", 4, "<II", False
    else:
        raise DecodeError(f"unknown message encoding {encoding!r}")
    if size < pos + 8:
        raise DecodeError(f"{size} bytes are too short for the header stamp")
    sec, nsec = struct.unpack_from(stamp_fmt, data, pos)
    pos += 8

    def string(pos: int, what: str) -> tuple[str, int]:
        if encoding == "cdr":
            pos = _align(pos, 4)
        if pos + 4 > size:
            raise DecodeError(f"message ends before the length of {what}")
        (length,) = struct.unpack_from(order + "I", data, pos)
        start, stop = pos + 4, pos + 4 + length
        if stop > size:
            raise DecodeError(f"{what} claims {length} bytes but the message has only {size - start} left")
        raw = data[start:stop]
        if nul:
            if length == 0 or raw[-1] != 0:
                raise DecodeError(f"{what} is not NUL-terminated")
            raw = raw[:-1]
        try:
            return raw.decode("utf-8"), stop
        except UnicodeDecodeError:
            raise DecodeError(f"{what} is not valid UTF-8") from None

    frame_id, pos = string(pos, "header.frame_id")
    child = ""
    if layout.child_frame:
        child, pos = string(pos, "child_frame_id")
    if encoding == "cdr":
        pos = _align(pos, 8)
    need = pos + 8 * layout.n_doubles
    if need > size:
        raise DecodeError(f"message has {size} bytes; {layout.name} with these frame ids needs {need}")
    values = struct.unpack_from(f"{order}{layout.n_doubles}d", data, pos)
    return sec * _NS + nsec, frame_id, child, values


def encode_pose_in_frame(stamps_ns: np.ndarray, frame_id: str, values: ArrayF) -> list[bytes]:
    """JSON ``foxglove.PoseInFrame`` messages; ``values (N, 7)`` = position xyz, orientation xyzw.

    Floats are written with Python's shortest round-trip representation (``repr``), so a JSON
    reader gets the same float64 back; non-finite values become ``null``.
    """
    values = np.asarray(values, dtype=np.float64)
    sec, nsec = split_stamp(stamps_ns, "json")
    frame = json.dumps(frame_id)
    template = (
        '{"timestamp":{"sec":%d,"nsec":%d},"frame_id":' + frame.replace("%", "%%") + ',"pose":{"position":'
        '{"x":%r,"y":%r,"z":%r},"orientation":{"x":%r,"y":%r,"z":%r,"w":%r}}}'
    )
    finite = np.isfinite(values).all(axis=1)
    out: list[bytes] = []
    for s, ns, row, ok in zip(sec.tolist(), nsec.tolist(), values.tolist(), finite.tolist()):
        if ok:
            out.append((template % (s, ns, *row)).encode())
        else:
            document = {
                "timestamp": {"sec": s, "nsec": ns},
                "frame_id": frame_id,
                "pose": {
                    "position": dict(zip("xyz", (v if np.isfinite(v) else None for v in row[:3]))),
                    "orientation": dict(zip("xyzw", (v if np.isfinite(v) else None for v in row[3:]))),
                },
            }
            out.append(json.dumps(document, separators=(",", ":")).encode())
    return out


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
