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
* undecodable message, non-finite values, zero quaternion, zero stamp among non-zero ones: drop
  the message;
* quaternion norm off 1 by more than ``quaternion_tolerance`` (default 1e-6): renormalise it;
* header stamps going backwards: sort the messages by stamp (stable);
* duplicate header stamps: keep the first message of each stamp.

Every repair is listed in the result's ``repairs`` (and issued as a
:class:`RecordingRepairWarning` by the replay functions). Empty files, files that are not MCAP
(ROS 1 ``.bag`` and ROS 2 ``.db3`` files get a conversion hint), unknown encodings or types, and
missing topics (the message lists the topics and types found) are always errors.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
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
from fkn_bench.recordings.codecs import DecodeError, decode_pose_in_frame, decode_stamped
from fkn_bench.recordings.schemas import canonical_type_name

__all__ = [
    "RecordingError",
    "TopicNotFoundError",
    "RecordingRepairWarning",
    "TopicInfo",
    "PoseSeries",
    "TwistSeries",
    "McapRecording",
    "POSE_TYPES",
    "TWIST_TYPES",
    "MCAP_MAGIC",
    "read_metadata",
    "list_topics",
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

_SUPPORTED = set(POSE_TYPES) | set(TWIST_TYPES)
_ENCODINGS = {"cdr": "ROS 2 CDR", "ros1": "ROS 1", "json": "JSON"}
_RECORD_HEAD = struct.Struct("<BQ")
_MESSAGE_HEAD = struct.Struct("<HIQQ")
_OPCODE_MESSAGE = 0x05


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


@dataclass
class _Decoded:
    """Decoded messages of one topic, in log-time order (undecodable ones dropped)."""

    type_name: str
    encoding: str
    indices: np.ndarray
    log: np.ndarray
    header: np.ndarray
    frame_id: str
    child_frame_id: str
    values: np.ndarray
    repairs: list[str]


def _describe(exc: BaseException) -> str:
    text = str(exc).strip()
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _seconds(ns: int) -> str:
    return f"{ns / _NS:.9f} s"


class McapRecording:
    """An MCAP file opened for reading pose topics.

    Opening checks that the file exists, is not empty and is MCAP (hints for ROS 1 ``.bag`` and
    ROS 2 ``.db3`` files), and reads its summary. A file without a valid end (truncated, or a
    writer that never finished) raises :class:`RecordingError` unless ``repair=True``, which reads
    it front to back up to the damage.

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
        if head.startswith(b"#ROSBAG"):
            raise self._error(
                "this is a ROS 1 bag (.bag), not MCAP; convert it with `mcap convert FILE.bag FILE.mcap` "
                "(the mcap CLI) and replay the .mcap"
            )
        if head.startswith(b"SQLite format 3"):
            raise self._error(
                "this is a ROS 2 sqlite3 bag (.db3), not MCAP; convert it with `ros2 bag convert` "
                "(storage 'mcap') or `mcap convert`, and replay the .mcap"
            )
        if not head.startswith(MCAP_MAGIC[: len(head)]) or len(head) < len(MCAP_MAGIC):
            if len(head) < len(MCAP_MAGIC) and MCAP_MAGIC.startswith(head):
                raise self._error(f"the file is truncated: {self.size} bytes, fewer than the MCAP magic")
            raise self._error(f"not an MCAP file (it starts with bytes {head[:8].hex(' ')}, not the MCAP magic)")

    def _open_summary(self) -> None:
        with self.path.open("rb") as fh:
            fh.seek(max(0, self.size - len(MCAP_MAGIC)))
            tail = fh.read()
            complete = self.size >= 2 * len(MCAP_MAGIC) and tail == MCAP_MAGIC
            problem = None
            if complete:
                try:
                    fh.seek(0)
                    reader = SeekingReader(fh, validate_crcs=True)
                    self._summary = reader.get_summary()
                except Exception as exc:  # any failure here means a damaged end of file
                    problem = f"its summary section cannot be read ({_describe(exc)})"
            else:
                problem = (
                    f"the file is truncated or was not closed properly: it does not end with the MCAP magic "
                    f"bytes ({self.size} bytes)"
                )
        if problem is not None:
            self._repair(
                f"{problem}. Pass repair=True to read the messages stored before the damage, or recover the "
                "file with `mcap recover`",
                f"{problem}; read the file front to back up to the damage",
            )
            self._summary = None
            self._scan_linear()
        elif self._summary is None or not self._summary.chunk_indexes:
            self._scan_linear()  # valid file without an index

    # ------------------------------------------------------------------ chunk and linear reading
    def _chunk_records(self, chunk: Chunk, where: str) -> list[Any] | None:
        """Records of ``chunk``; None if it is corrupt and repair is on."""
        data = self._chunk_data(chunk, where)
        if data is None:
            return None
        try:
            return breakup_chunk(Chunk(compression="", data=data, message_start_time=chunk.message_start_time,
                                       message_end_time=chunk.message_end_time, uncompressed_crc=0,
                                       uncompressed_size=len(data)))
        except Exception as exc:
            self._repair(
                f"{where} is corrupt ({_describe(exc)}). Pass repair=True to skip damaged chunks (their messages are lost)",
                f"skipped {where}, which is corrupt ({_describe(exc)})",
            )
            return None

    def _scan_linear(self) -> None:
        """Read every record front to back (files without an index, or damaged ones)."""
        schemas: dict[int, Schema] = {}
        raw: dict[int, _Raw] = {}
        position = 0

        def message(record: Message) -> None:
            nonlocal position
            entry = self._linear_channels.get(record.channel_id)
            if entry is None:
                raise self._error(f"message at record {position} refers to unknown channel {record.channel_id}")
            self._linear_counts[record.channel_id] = self._linear_counts.get(record.channel_id, 0) + 1
            if canonical_type_name(entry[1].name if entry[1] else "") in _SUPPORTED:
                raw.setdefault(record.channel_id, _Raw(entry[0], entry[1])).messages.append(
                    (record.log_time, position, record.data)
                )
            position += 1

        def handle(record: Any) -> None:
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                self._linear_channels[record.id] = (record, schemas.get(record.schema_id))
            elif isinstance(record, Message):
                message(record)
            elif isinstance(record, Metadata):
                self._linear_metadata.append(record)

        count = 0
        with self.path.open("rb") as fh:
            records: Iterator[Any] = StreamReader(fh, emit_chunks=True, validate_crcs=False).records
            while True:
                try:
                    record = next(records)
                except StopIteration:
                    break
                except Exception as exc:
                    problem = f"record {count} (near byte {fh.tell()}), which cannot be read ({_describe(exc)})"
                    self._repair(
                        f"{problem}; the file is truncated or corrupt. Pass repair=True to use the messages before "
                        "the damage",
                        f"stopped reading at {problem}",
                    )
                    break
                count += 1
                if isinstance(record, Chunk):
                    inner = self._chunk_records(record, f"the chunk in record {count - 1} (ending at byte {fh.tell()})")
                    for item in inner or ():
                        handle(item)
                else:
                    handle(record)
        self._linear = raw

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
            out[channel.topic] = TopicInfo(
                channel.topic,
                schema.name if schema else "",
                schema.encoding if schema else "",
                channel.message_encoding,
                n,
            )
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
        records: list[Metadata] = []
        if self._linear is not None:
            records = self._linear_metadata
        else:
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
        if not wanted:
            return
        if self._linear is not None:
            for topic in wanted:
                self._cache[topic] = [r for r in self._linear.values() if r.channel.topic == topic]
        else:
            self._cache.update(self._read_indexed(set(wanted)))

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

    def _chunk_data(self, chunk: Chunk, where: str) -> bytes | None:
        """Decompressed, CRC-checked data of ``chunk``; None if it is corrupt and repair is on."""
        problem = None
        data = b""
        try:
            if chunk.compression == "zstd":
                data = zstandard.decompress(chunk.data, max_output_size=chunk.uncompressed_size)
            elif chunk.compression == "lz4":
                data = lz4.frame.decompress(chunk.data)
            elif chunk.compression == "":
                data = chunk.data
            else:
                problem = f"it uses chunk compression {chunk.compression!r}, which this reader does not support (zstd, lz4 or none)"
        except Exception as exc:
            problem = f"its {chunk.compression} data cannot be decompressed ({_describe(exc)})"
        if problem is None:
            if len(data) != chunk.uncompressed_size:
                problem = f"{len(data)} bytes decompressed, {chunk.uncompressed_size} expected"
            elif chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
                problem = "its CRC does not match its data"
        if problem is None:
            return data
        self._repair(
            f"{where} is corrupt: {problem}. Pass repair=True to skip damaged chunks (their messages are lost)",
            f"skipped {where}, which is corrupt: {problem}",
        )
        return None

    def _read_indexed(self, topics: set[str]) -> dict[str, list[_Raw]]:
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
                where = f"chunk {number} (bytes {index.chunk_start_offset}-{index.chunk_start_offset + index.chunk_length})"
                try:
                    if index.chunk_start_offset + index.chunk_length > self.size:
                        raise ValueError(f"it would end past the end of the file ({self.size} bytes)")
                    fh.seek(index.chunk_start_offset + 1 + 8)
                    chunk = Chunk.read(ReadDataStream(fh))
                except Exception as exc:
                    self._repair(
                        f"{where} cannot be read ({_describe(exc)}); the file is corrupt. Pass repair=True to skip "
                        "damaged chunks",
                        f"skipped {where}, which cannot be read ({_describe(exc)})",
                    )
                    continue
                data = self._chunk_data(chunk, where)
                if data is None:
                    continue
                # walk the records: opcode u8, length u64; a message is channel u16, sequence u32,
                # log_time u64, publish_time u64, payload
                pos, end, serial = 0, len(data), index.chunk_start_offset << 24
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
                        f"{where} is corrupt: its records cannot be parsed ({exc}). Pass repair=True to skip damaged chunks",
                        f"{where}: stopped at a damaged record ({exc})",
                    )
        out: dict[str, list[_Raw]] = {topic: [] for topic in topics}
        for entry in raw.values():
            if entry.messages:
                out[entry.channel.topic].append(entry)
        return out

    # ------------------------------------------------------------------ decoding
    def _decode(self, topic: str, role: str, allowed: tuple[str, ...]) -> _Decoded:
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
        rows: list[tuple[int, int, int, str, str, tuple[float, ...]]] = []
        dropped: list[int] = []
        for i, (log_time, _, data) in enumerate(self._raw(topic).messages):
            try:
                if encoding == "json":
                    stamp, frame, values = decode_pose_in_frame(data)
                    child = ""
                else:
                    stamp, frame, child, values = decode_stamped(type_name, encoding, data)
            except (DecodeError, struct.error) as exc:
                if not self.repair:
                    raise self._error(
                        f"{role} topic {topic!r}: message #{i} (log time {_seconds(log_time)}) cannot be decoded as "
                        f"{info.schema_name} ({_ENCODINGS[encoding]}): {exc}. Pass repair=True to drop undecodable "
                        "messages",
                        topic=topic,
                        index=i,
                    ) from None
                dropped.append(i)
                continue
            rows.append((i, log_time, stamp, frame, child, values))
        if not rows:
            raise self._error(f"{role} topic {topic!r} has no decodable messages", topic=topic)
        indices, log, header, frames, children, values = zip(*rows)
        return _Decoded(
            type_name=type_name,
            encoding=encoding,
            indices=np.array(indices, dtype=np.int64),
            log=np.array(log, dtype=np.int64),
            header=np.array(header, dtype=np.int64),
            frame_id=frames[0],
            child_frame_id=children[0],
            values=np.array(values, dtype=np.float64),
            repairs=[f"{topic}: dropped {len(dropped)} undecodable message(s) (first: #{dropped[0]})"] if dropped else [],
        )

    def _stamps(self, topic: str, role: str, d: _Decoded, time_source: str, notes: list[str]) -> tuple[np.ndarray, np.ndarray, str]:
        """Stamps per ``time_source``; returns (stamps, rows to keep, source used)."""
        keep = np.ones(len(d.indices), dtype=bool)
        if time_source == "log":
            return d.log.copy(), keep, "log"
        if time_source not in ("auto", "header"):
            raise ValueError(f"time_source must be 'auto', 'header' or 'log' (got {time_source!r})")
        zero = d.header == 0
        if zero.all():
            if time_source == "auto":
                notes.append(f"{topic}: every header stamp is zero; used the MCAP log times instead")
                return d.log.copy(), keep, "log"
            raise self._error(
                f"{role} topic {topic!r}: every header stamp is zero; use time_source='log' (or 'auto')",
                topic=topic, index=int(d.indices[0]),
            )
        if zero.any():
            first = int(d.indices[np.argmax(zero)])
            self._repair(
                f"{role} topic {topic!r}: message #{first} has a zero header stamp while others do not. "
                "Pass repair=True to drop such messages, or time_source='log'",
                f"{topic}: dropped {int(zero.sum())} message(s) with a zero header stamp (first: #{first})",
                d.repairs, topic=topic, index=first,
            )
            keep &= ~zero
        return d.header.copy(), keep, "header"

    def _order(self, topic: str, role: str, stamps: np.ndarray, indices: np.ndarray, repairs: list[str]) -> np.ndarray:
        """Positions making ``stamps`` strictly increasing (sort, drop duplicates) or raise."""
        order = np.arange(len(stamps))
        back = np.flatnonzero(np.diff(stamps) < 0) + 1
        if len(back):
            i = int(back[0])
            self._repair(
                f"{role} topic {topic!r}: message #{int(indices[i])} has stamp {_seconds(int(stamps[i]))}, earlier than "
                f"message #{int(indices[i - 1])} ({_seconds(int(stamps[i - 1]))}): the time stamps are not monotonic. "
                "Pass repair=True to sort the messages by stamp",
                f"{topic}: sorted the messages by stamp ({len(back)} went backwards; first: #{int(indices[i])})",
                repairs, topic=topic, index=int(indices[i]),
            )
            order = np.argsort(stamps, kind="stable")
        same = np.flatnonzero(np.diff(stamps[order]) == 0) + 1
        if len(same):
            i = int(same[0])
            this, before = int(indices[order[i]]), int(indices[order[i - 1]])
            self._repair(
                f"{role} topic {topic!r}: message #{this} has the same stamp {_seconds(int(stamps[order[i]]))} as "
                f"message #{before} (duplicate time stamps). Pass repair=True to keep only the first message of each stamp",
                f"{topic}: dropped {len(same)} message(s) with a duplicate stamp, keeping the first of each "
                f"(first dropped: #{this})",
                repairs, topic=topic, index=this,
            )
            order = np.delete(order, same)
        return order

    def _rows(self, topic: str, role: str, d: _Decoded, time_source: str, poses: np.ndarray | None,
              twists: np.ndarray | None, quaternion_tolerance: float = 1e-6) -> tuple[np.ndarray, dict[str, Any]]:
        """The usable rows of ``d`` in stamp order and the :class:`_Series` fields they make: drops
        (or refuses) non-finite values and zero quaternions, renormalises ``poses`` in place."""
        notes: list[str] = []
        stamps, keep, source = self._stamps(topic, role, d, time_source, notes)
        ok = np.ones(len(d.indices), dtype=bool)
        for array in (poses, twists):
            if array is not None:
                ok &= np.isfinite(array).all(axis=1)
        zero_q = np.zeros(len(d.indices), dtype=bool)
        if poses is not None:
            zero_q = ok & (np.linalg.norm(np.nan_to_num(poses[:, :4]), axis=1) < 1e-9)
            ok &= ~zero_q
        bad = keep & ~ok
        if bad.any():
            i = int(np.argmax(bad))
            what = "a zero quaternion" if zero_q[i] else "a non-finite value (NaN or infinity)"
            self._repair(
                f"{role} topic {topic!r}: message #{int(d.indices[i])} has {what}; pass repair=True to drop such messages",
                f"{topic}: dropped {int(bad.sum())} message(s) with non-finite values or zero quaternions "
                f"(first: #{int(d.indices[i])})",
                d.repairs, topic=topic, index=int(d.indices[i]),
            )
        keep &= ok
        if poses is not None:
            norms = np.linalg.norm(poses[:, :4], axis=1)
            bad_norm = keep & (np.abs(norms - 1.0) > quaternion_tolerance)
            if bad_norm.any():
                i = int(np.argmax(bad_norm))
                self._repair(
                    f"{role} topic {topic!r}: message #{int(d.indices[i])} has a quaternion of norm {norms[i]:.9g}, not 1 "
                    f"(tolerance {quaternion_tolerance:g}); pass repair=True to renormalise such quaternions, or a "
                    "larger quaternion_tolerance",
                    f"{topic}: renormalised {int(bad_norm.sum())} quaternion(s) with a norm off 1 by more than "
                    f"{quaternion_tolerance:g} (first: #{int(d.indices[i])}, norm {norms[i]:.9g})",
                    d.repairs, topic=topic, index=int(d.indices[i]),
                )
                poses[bad_norm, :4] /= norms[bad_norm, None]
        rows = np.flatnonzero(keep)
        order = rows[self._order(topic, role, stamps[rows], d.indices[rows], d.repairs)]
        if len(order) == 0:
            raise self._error(f"{role} topic {topic!r} has no usable messages", topic=topic)
        return order, dict(topic=topic, type_name=d.type_name, encoding=d.encoding, stamps_ns=stamps[order],
                           indices=d.indices[order], time_source=source, repairs=tuple(d.repairs), notes=tuple(notes))

    def read_poses(
        self,
        topic: str,
        *,
        role: str = "pose",
        time_source: str = "auto",
        quaternion_tolerance: float = 1e-6,
    ) -> PoseSeries:
        """Validated poses of ``topic`` (see module docstring for the checks and repairs)."""
        d = self._decode(topic, role, POSE_TYPES)
        values = d.values
        # ROS order: position(3), orientation xyzw(4) [, pose cov(36), twist linear(3), angular(3), ...]
        poses = np.concatenate([xyzw_to_wxyz(values[:, 3:7]), values[:, 0:3]], axis=1)
        twists = None
        if d.type_name == "nav_msgs/Odometry":
            twists = np.concatenate([values[:, 46:49], values[:, 43:46]], axis=1)
        order, common = self._rows(topic, role, d, time_source, poses, twists, quaternion_tolerance)
        return PoseSeries(**common, poses=poses[order], frame_id=d.frame_id, child_frame_id=d.child_frame_id,
                          twists=None if twists is None else twists[order])

    def read_twists(self, topic: str, *, role: str = "twist", time_source: str = "auto") -> TwistSeries:
        """Validated twists of ``topic`` (``TwistStamped``, or the twist part of ``Odometry``)."""
        d = self._decode(topic, role, TWIST_TYPES)
        values = d.values[:, 43:49] if d.type_name == "nav_msgs/Odometry" else d.values
        twists = np.concatenate([values[:, 3:6], values[:, 0:3]], axis=1)  # angular, linear
        order, common = self._rows(topic, role, d, time_source, None, twists)
        frame_id = d.child_frame_id if d.type_name == "nav_msgs/Odometry" else d.frame_id
        return TwistSeries(**common, twists=twists[order], frame_id=frame_id)


def read_metadata(path: str | Path) -> dict[str, dict[str, str]]:
    """Metadata records of an MCAP file (see :class:`McapRecording`)."""
    return McapRecording(path).metadata()


def list_topics(path: str | Path) -> dict[str, TopicInfo]:
    """Topics of an MCAP file with types, encodings and message counts."""
    return McapRecording(path).topics()
