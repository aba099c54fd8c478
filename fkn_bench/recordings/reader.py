"""Read pose and twist topics from MCAP files, with clear errors and documented repairs.

Supported messages (by schema name and MCAP message encoding):

* ROS 2 (``cdr``) and ROS 1 (``ros1``): ``geometry_msgs/PoseStamped``,
  ``geometry_msgs/PoseWithCovarianceStamped``, ``nav_msgs/Odometry`` (poses, and Odometry's
  twist) and ``geometry_msgs/TwistStamped`` (twists); ``geometry_msgs/msg/X`` and
  ``geometry_msgs/X`` name the same type.
* ``json``: ``foxglove.PoseInFrame``.

Messages of a topic are taken in log-time order (ties in file order); "message #i" in errors and
reports counts from 0 in that order. Time stamps are the message's own (``header.stamp``,
``timestamp`` for Foxglove); with ``time_source="auto"`` a topic whose stamps are all zero (an
unset header, as some simulators publish) uses the MCAP log time instead, and says so.

Problems, and what ``repair=True`` does about them (without it, each raises
:class:`RecordingError` naming the file, the topic and the message):

* file truncated or not closed (no footer), or an unreadable summary: read the records before
  the damage, front to back;
* corrupt chunk (CRC mismatch, undecodable or unknown compression): skip it (its messages are
  lost);
* undecodable message, non-finite values, implausible values (a position beyond +-1e6 m, a
  rate beyond +-1e3 rad/s or m/s: :mod:`fkn_bench.recordings.plausibility`), zero quaternion,
  zero stamp among non-zero ones: drop the message;
* quaternion norm off 1 by more than ``quaternion_tolerance`` (default 1e-6): renormalise it;
* header stamps going backwards: sort the messages by stamp (stable);
* duplicate header stamps: keep the first message of each stamp.

Every repair is listed in the result's ``repairs`` (and issued as a
:class:`RecordingRepairWarning` by the replay functions). Empty files, files that are not MCAP
(ROS 1 ``.bag`` and ROS 2 ``.db3`` files get a conversion hint), unknown encodings or types, and
missing topics (the message lists the topics and types found) are always errors.
"""

from __future__ import annotations

import itertools
import struct
import zlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import lz4.frame
import numpy as np
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

from fkn_bench.geometry.quaternion import xyzw_to_wxyz
from fkn_bench.recordings.codecs import DecodeError, decode_stamped
from fkn_bench.recordings.plausibility import component_limits, first_implausible
from fkn_bench.recordings.schemas import canonical_type_name
from fkn_bench.types import STATE_NAMES
from fkn_bench.wording import option, option_name

__all__ = [
    "RecordingError", "TopicNotFoundError", "RecordingRepairWarning", "TopicInfo", "PoseSeries",
    "TwistSeries", "McapRecording", "POSE_TYPES", "TWIST_TYPES", "MCAP_MAGIC", "read_metadata",
    "list_topics"
]

MCAP_MAGIC = b"\x89MCAP0\r\n"
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

_ODOMETRY = "nav_msgs/Odometry"
_SUPPORTED = set(POSE_TYPES) | set(TWIST_TYPES)
_ENCODINGS = {"cdr": "ROS 2 CDR", "ros1": "ROS 1", "json": "JSON"}
_RECORD_HEAD = struct.Struct("<BQ")
_MESSAGE_HEAD = struct.Struct("<HIQQ")
_OPCODE_MESSAGE = 0x05
_OTHER_FORMATS = {  # file start -> what the file is and how to convert it
    b"#ROSBAG": "this is a ROS 1 bag (.bag), not MCAP; convert it with `mcap convert FILE.bag FILE.mcap` "
    "(the mcap CLI) and replay the .mcap",
    b"SQLite format 3": "this is a ROS 2 sqlite3 bag (.db3), not MCAP; convert it with `ros2 bag convert` "
    "(storage 'mcap') or `mcap convert`, and replay the .mcap",
}
_DECOMPRESS = {
    "zstd": lambda chunk: zstandard.decompress(chunk.data, max_output_size=chunk.uncompressed_size),
    "lz4": lambda chunk: lz4.frame.decompress(chunk.data),
    "": lambda chunk: chunk.data,
}


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
    """A documented repair was applied to a recording (see :mod:`fkn_bench.recordings.reader`)."""


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
        indices: ``(N,)`` message numbers (log-time order) the rows come from.
        time_source: ``"header"`` or ``"log"``.
        repairs, notes: what was repaired, and other remarks.
    """

    poses: np.ndarray
    child_frame_id: str
    twists: np.ndarray | None


@dataclass(frozen=True, eq=False, kw_only=True)
class TwistSeries(_Series):
    """Validated twists of one topic: ``twists (N, 6)`` = ``[angular(3), linear(3)]`` in
    ``frame_id``; other attributes as :class:`PoseSeries`."""

    twists: np.ndarray


@dataclass
class _Raw:
    """Raw messages of one topic: (log_time, file position, data) and the channel/schema."""

    channel: Channel
    schema: Schema | None
    messages: list[tuple[int, int, bytes]] = field(default_factory=list)


def _describe(exc: BaseException) -> str:
    text = str(exc).strip()
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _seconds(ns: int) -> str:
    return f"{ns / _NS:.9f} s"


class McapRecording:
    """An MCAP file opened for reading pose topics.

    Opening checks the file (see the module docstring for the errors and repairs) and reads its
    summary.

    Args:
        path: the ``.mcap`` file.
        repair: apply the documented repairs instead of raising (see module docstring).
    """

    def __init__(self, path: str | Path, *, repair: bool = False) -> None:
        self.path = Path(path)
        self.repair = bool(repair)
        self.repairs: list[str] = []
        self.notes: list[str] = []
        self._check_file()
        self._summary = None
        self._linear: dict[int, _Raw] | None = None
        self._linear_metadata: list[Metadata] = []
        self._linear_channels: dict[int, tuple[Channel, Schema | None]] = {}
        self._linear_counts: dict[int, int] = {}
        self._cache: dict[str, list[_Raw]] = {}
        self._open_summary()

    # ------------------------------------------------------------------ opening
    def _error(self, message: str, **where: Any) -> RecordingError:
        return RecordingError(f"{self.path}: {message}", path=self.path, **where)

    def _repair(self, error: str, note: str, repairs: list[str] | None = None, **where: Any) -> None:
        """Raise ``error`` (which says how to repair) unless repairing; else record ``note`` in
        ``repairs`` (default: the file's)."""
        if not self.repair:
            raise self._error(error, **where)
        (self.repairs if repairs is None else repairs).append(note)

    def _skip_chunk(self, where: str, problem: str) -> None:
        self._repair(
            f"{where} {problem}. Pass {option('repair')} to skip damaged chunks (their messages are lost)",
            f"skipped {where}, which {problem}",
        )

    def _check_file(self) -> None:
        path = self.path
        if not path.exists():
            raise RecordingError(f"recording not found: {path}", path=path)
        if not path.is_file():
            raise RecordingError(f"{path} is not a file", path=path)
        self.size = path.stat().st_size
        if self.size == 0:
            raise self._error("the file is empty (0 bytes); it is not an MCAP recording")
        with path.open("rb") as fh:
            head = fh.read(16)
        for start, hint in _OTHER_FORMATS.items():
            if head.startswith(start):
                raise self._error(hint)
        if not head.startswith(MCAP_MAGIC):
            if MCAP_MAGIC.startswith(head):
                raise self._error(f"the file is truncated: {self.size} bytes, fewer than the MCAP magic")
            raise self._error(f"not an MCAP file (it starts with bytes {head[:8].hex(' ')}, not the MCAP magic)")

    def _open_summary(self) -> None:
        problem = None
        with self.path.open("rb") as fh:
            fh.seek(max(0, self.size - len(MCAP_MAGIC)))
            if self.size < 2 * len(MCAP_MAGIC) or fh.read() != MCAP_MAGIC:
                problem = (
                    f"the file is truncated or was not closed properly: it does not end with the MCAP magic "
                    f"bytes ({self.size} bytes)"
                )
            else:
                try:
                    fh.seek(0)
                    self._summary = SeekingReader(fh, validate_crcs=True).get_summary()
                except Exception as exc:  # any failure here means a damaged end of file
                    problem = f"its summary section cannot be read ({_describe(exc)})"
        if problem is not None:
            self._repair(
                f"{problem}. Pass {option('repair')} to read the messages stored before the damage, or recover the "
                "file with `mcap recover`",
                f"{problem}; read the file front to back up to the damage",
            )
        if self._summary is None or not self._summary.chunk_indexes:
            self._scan_linear()  # a damaged file, or a valid one without an index

    # ------------------------------------------------------------------ chunk and linear reading
    def _chunk_data(self, chunk: Chunk, where: str) -> bytes | None:
        """Decompressed, CRC-checked data of ``chunk``; None if it is corrupt and repair is on."""
        decompress = _DECOMPRESS.get(chunk.compression)
        if decompress is None:
            problem = (
                f"it uses chunk compression {chunk.compression!r}, which this reader does not support "
                "(zstd, lz4 or none)"
            )
        else:
            try:
                data = decompress(chunk)
            except Exception as exc:
                problem = f"its {chunk.compression} data cannot be decompressed ({_describe(exc)})"
            else:
                if len(data) != chunk.uncompressed_size:
                    problem = f"{len(data)} bytes decompressed, {chunk.uncompressed_size} expected"
                elif chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
                    problem = "its CRC does not match its data"
                else:
                    return data
        self._skip_chunk(where, f"is corrupt: {problem}")
        return None

    def _chunk_records(self, chunk: Chunk, where: str) -> list[Any]:
        """Records of ``chunk``; none if it is corrupt and repair is on."""
        data = self._chunk_data(chunk, where)
        if data is None:
            return []
        try:
            return breakup_chunk(
                replace(chunk, compression="", data=data, uncompressed_crc=0, uncompressed_size=len(data))
            )
        except Exception as exc:
            self._skip_chunk(where, f"is corrupt ({_describe(exc)})")
            return []

    def _scan_linear(self) -> None:
        """Read every record front to back (files without an index, or damaged ones)."""
        schemas: dict[int, Schema] = {}
        raw: dict[int, _Raw] = {}
        position = 0  # messages so far, in file order

        def handle(record: Any) -> None:
            nonlocal position
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                self._linear_channels[record.id] = (record, schemas.get(record.schema_id))
            elif isinstance(record, Metadata):
                self._linear_metadata.append(record)
            elif isinstance(record, Message):
                cid = record.channel_id
                if cid not in self._linear_channels:
                    raise self._error(f"message at record {position} refers to unknown channel {cid}")
                self._linear_counts[cid] = self._linear_counts.get(cid, 0) + 1
                channel, schema = self._linear_channels[cid]
                if canonical_type_name(schema.name if schema else "") in _SUPPORTED:
                    entry = raw.setdefault(cid, _Raw(channel, schema))
                    entry.messages.append((record.log_time, position, record.data))
                position += 1

        with self.path.open("rb") as fh:
            records: Iterator[Any] = StreamReader(fh, emit_chunks=True, validate_crcs=False).records
            for count in itertools.count():
                try:
                    record = next(records)
                except StopIteration:
                    break
                except Exception as exc:
                    problem = f"record {count} (near byte {fh.tell()}), which cannot be read ({_describe(exc)})"
                    self._repair(
                        f"{problem}; the file is truncated or corrupt. Pass {option('repair')} to use the messages before "
                        "the damage",
                        f"stopped reading at {problem}",
                    )
                    break
                if isinstance(record, Chunk):
                    items = self._chunk_records(record, f"the chunk in record {count} (ending at byte {fh.tell()})")
                else:
                    items = [record]
                for item in items:
                    handle(item)
        self._linear = raw

    def _read_indexed(self, topics: set[str]) -> dict[int, _Raw]:
        """Raw messages of the channels of ``topics``, read through the chunk index."""
        summary = self._summary
        assert summary is not None
        channels = {cid: ch for cid, ch in summary.channels.items() if ch.topic in topics}
        raw = {cid: _Raw(ch, summary.schemas.get(ch.schema_id)) for cid, ch in channels.items()}
        ordered = sorted(enumerate(summary.chunk_indexes), key=lambda item: item[1].chunk_start_offset)
        unpack = _MESSAGE_HEAD.unpack_from
        with self.path.open("rb") as fh:
            for number, index in ordered:
                if index.message_index_offsets and not channels.keys() & index.message_index_offsets.keys():
                    continue
                start, stop = index.chunk_start_offset, index.chunk_start_offset + index.chunk_length
                where = f"chunk {number} (bytes {start}-{stop})"
                try:
                    if stop > self.size:
                        raise ValueError(f"it would end past the end of the file ({self.size} bytes)")
                    fh.seek(start + 1 + 8)
                    chunk = Chunk.read(ReadDataStream(fh))
                except Exception as exc:
                    self._skip_chunk(where, f"cannot be read ({_describe(exc)})")
                    continue
                data = self._chunk_data(chunk, where)
                if data is None:
                    continue
                # walk the records: opcode u8, length u64; a message is channel u16, sequence u32,
                # log_time u64, publish_time u64, payload
                pos, end, serial = 0, len(data), start << 24
                try:
                    while pos < end:
                        opcode, length = _RECORD_HEAD.unpack_from(data, pos)
                        body = pos + 9
                        pos = body + length
                        if pos > end:
                            raise ValueError(f"a record runs past the end of the chunk ({pos} > {end})")
                        if opcode == _OPCODE_MESSAGE:
                            channel_id, _, log_time, _ = unpack(data, body)
                            entry = raw.get(channel_id)
                            if entry is not None:
                                entry.messages.append((log_time, serial, data[body + 22 : pos]))
                        serial += 1
                except (struct.error, ValueError) as exc:
                    self._repair(
                        f"{where} is corrupt: its records cannot be parsed ({exc}). Pass {option('repair')} to skip damaged chunks",
                        f"{where}: stopped at a damaged record ({exc})",
                    )
        return raw

    # ------------------------------------------------------------------ queries
    def topics(self) -> dict[str, TopicInfo]:
        """Topics with their types, encodings and message counts, by topic name."""
        out: dict[str, TopicInfo] = {}
        if self._linear is not None:
            items = [(cid, ch, sc) for cid, (ch, sc) in self._linear_channels.items()]
            counts = self._linear_counts
        else:
            summary = self._summary
            assert summary is not None
            items = [(cid, ch, summary.schemas.get(ch.schema_id)) for cid, ch in summary.channels.items()]
            counts = dict(summary.statistics.channel_message_counts) if summary.statistics else None
        for cid, channel, schema in items:
            n = None if counts is None else counts.get(cid, 0)
            previous = out.get(channel.topic)
            if previous is not None and n is not None and previous.message_count is not None:
                n += previous.message_count
            name, encoding = (schema.name, schema.encoding) if schema else ("", "")
            out[channel.topic] = TopicInfo(channel.topic, name, encoding, channel.message_encoding, n)
        return out

    def describe_topics(self) -> str:
        topics = self.topics()
        if not topics:
            return "the recording has no topics"
        width = max(len(t) for t in topics)
        lines = [f"  {info.topic:<{width}}  {info.describe()[len(info.topic) + 2:]}" for info in topics.values()]
        return "topics in this recording:\n" + "\n".join(lines)

    def metadata(self) -> dict[str, dict[str, str]]:
        """Metadata records ``{name: {key: value}}`` (later records of a name win)."""
        records: list[Metadata] = self._linear_metadata
        if self._linear is None:
            try:
                with self.path.open("rb") as fh:
                    records = list(SeekingReader(fh).iter_metadata())
            except Exception as exc:
                self.notes.append(f"metadata could not be read ({type(exc).__name__}: {exc})")
        return {record.name: dict(record.metadata) for record in records}

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

    def prefetch(self, topics: Iterable[str]) -> None:
        """Read the raw messages of several topics in one pass over the file (cached)."""
        wanted = [t for t in dict.fromkeys(topics) if t not in self._cache]
        if wanted:
            raw = self._linear if self._linear is not None else self._read_indexed(set(wanted))
            for topic in wanted:
                self._cache[topic] = [r for r in raw.values() if r.channel.topic == topic and r.messages]

    def _raw(self, topic: str) -> _Raw:
        """Raw messages of ``topic`` in log-time order (ties in file order)."""
        self.prefetch([topic])
        parts = self._cache[topic]
        if not parts:
            raise self._error(f"topic {topic!r} has no readable messages", topic=topic)
        schemas = {(p.schema.name if p.schema else "", p.channel.message_encoding) for p in parts}
        if len(schemas) > 1:
            raise self._error(f"topic {topic!r} mixes several types/encodings {sorted(schemas)}", topic=topic)
        merged = _Raw(parts[0].channel, parts[0].schema, [m for p in parts for m in p.messages])
        merged.messages.sort(key=lambda m: (m[0], m[1]))
        return merged

    # ------------------------------------------------------------------ decoding and checks
    def _series(
        self, topic: str, role: str, allowed: tuple[str, ...], time_source: str, with_poses: bool,
        quaternion_tolerance: float = 1e-6,
    ) -> dict[str, Any]:
        """The fields of a :class:`PoseSeries` of ``topic`` (``poses`` None unless ``with_poses``,
        ``twists`` None unless the type has a twist): the messages that pass the checks of the
        module docstring (or are repaired), in stamp order."""
        info = self.require_topic(topic, role)
        type_name, encoding = info.type_name, info.message_encoding
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
        for i, (log_time, _, data) in enumerate(self._raw(topic).messages):
            try:
                stamp, frame, child, values = decode_stamped(type_name, encoding, data)
            except (DecodeError, struct.error) as exc:
                dropped.append((i, log_time, exc))
                continue
            rows.append((i, log_time, stamp, frame, child, values))
        if dropped:
            i, log_time, exc = dropped[0]
            refuse(
                i,
                f"(log time {_seconds(log_time)}) cannot be decoded as {info.schema_name} ({_ENCODINGS[encoding]}): "
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
                notes.append(f"{topic}: every header stamp is zero; used the MCAP log times instead")
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

        # values: ROS order position(3), orientation xyzw(4) [, pose cov(36), twist linear(3) angular(3), ...]
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
        return dict(
            topic=topic, type_name=type_name, encoding=encoding, stamps_ns=stamps[order], indices=indices[order],
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
        del fields["poses"]
        child_frame_id = fields.pop("child_frame_id")
        if fields["type_name"] == _ODOMETRY:
            fields["frame_id"] = child_frame_id
        return TwistSeries(**fields)


def read_metadata(path: str | Path) -> dict[str, dict[str, str]]:
    """Metadata records of an MCAP file (see :class:`McapRecording`)."""
    return McapRecording(path).metadata()


def list_topics(path: str | Path) -> dict[str, TopicInfo]:
    """Topics of an MCAP file with types, encodings and message counts."""
    return McapRecording(path).topics()
