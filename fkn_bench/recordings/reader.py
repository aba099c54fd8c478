"""Read pose and twist topics from MCAP files, with clear errors and documented repairs.

:class:`McapRecording` finds a topic's messages in the file; decoding, the checks of the
messages and their repairs are :class:`~fkn_bench.recordings.base.Recording`'s (the messages
supported, the problems and repairs are listed in :mod:`fkn_bench.recordings.base`). The log time
of a message is its MCAP ``log_time``.

Problems of the file, and what ``repair=True`` does about them (without it, each raises
:class:`~fkn_bench.recordings.base.RecordingError` naming the file):

* file truncated or not closed (no footer), or an unreadable summary: read the records before
  the damage, front to back;
* corrupt chunk (CRC mismatch, undecodable or unknown compression): skip it (its messages are
  lost).

Empty files and files that are not MCAP are always errors (ROS 1 ``.bag`` and ROS 2 ``.db3``
files are named as such: :func:`~fkn_bench.recordings.opening.open_recording` reads them).
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
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

from fkn_bench.recordings.base import (
    POSE_TYPES,
    TWIST_TYPES,
    PoseSeries,
    Recording,
    RecordingError,
    RecordingRepairWarning,
    TopicInfo,
    TopicNotFoundError,
    TwistSeries,
    describe_exception,
)
from fkn_bench.recordings.schemas import canonical_type_name
from fkn_bench.wording import option

__all__ = [
    "RecordingError", "TopicNotFoundError", "RecordingRepairWarning", "TopicInfo", "PoseSeries",
    "TwistSeries", "McapRecording", "POSE_TYPES", "TWIST_TYPES", "MCAP_MAGIC"
]

MCAP_MAGIC = b"\x89MCAP0\r\n"
_RECORD_HEAD = struct.Struct("<BQ")
_MESSAGE_HEAD = struct.Struct("<HIQQ")
_OPCODE_MESSAGE = 0x05
_SUPPORTED = set(POSE_TYPES) | set(TWIST_TYPES)
OTHER_FORMATS: dict[bytes, str] = {  # file start -> what the file is
    b"#ROSBAG": "a ROS 1 bag (.bag)",
    b"SQLite format 3": "a ROS 2 sqlite3 bag (.db3)",
}
"""Starts of the bag files that :func:`~fkn_bench.recordings.opening.open_recording` reads with
:class:`~fkn_bench.recordings.bags.BagRecording`, and what they are."""
_DECOMPRESS = {
    "zstd": lambda chunk: zstandard.decompress(chunk.data, max_output_size=chunk.uncompressed_size),
    "lz4": lambda chunk: lz4.frame.decompress(chunk.data),
    "": lambda chunk: chunk.data,
}


@dataclass
class _Raw:
    """Raw messages of one topic: (log_time, file position, data) and the channel/schema."""

    channel: Channel
    schema: Schema | None
    messages: list[tuple[int, int, bytes]] = field(default_factory=list)


class McapRecording(Recording):
    """An MCAP file opened for reading pose topics.

    Opening checks the file (see the module docstring for the errors and repairs) and reads its
    summary.

    Args:
        path: the ``.mcap`` file.
        repair: apply the documented repairs instead of raising (see module docstring).
    """

    def __init__(self, path: str | Path, *, repair: bool = False) -> None:
        super().__init__(path, repair=repair)
        self._check_file()
        self._summary = None
        self._linear: dict[int, _Raw] | None = None
        self._linear_metadata: list[Metadata] = []
        self._linear_channels: dict[int, tuple[Channel, Schema | None]] = {}
        self._linear_counts: dict[int, int] = {}
        self._cache: dict[str, list[_Raw]] = {}
        self._open_summary()

    # ------------------------------------------------------------------ opening
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
        for start, what in OTHER_FORMATS.items():
            if head.startswith(start):
                raise self._error(
                    f"this is {what}, not MCAP; open it with fkn_bench.recordings.open_recording, which reads bags"
                )
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
                    problem = f"its summary section cannot be read ({describe_exception(exc)})"
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
                problem = f"its {chunk.compression} data cannot be decompressed ({describe_exception(exc)})"
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
            self._skip_chunk(where, f"is corrupt ({describe_exception(exc)})")
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
                    problem = f"record {count} (near byte {fh.tell()}), which cannot be read ({describe_exception(exc)})"
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
                    self._skip_chunk(where, f"cannot be read ({describe_exception(exc)})")
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

    def prefetch(self, topics: Iterable[str]) -> None:
        """Read the raw messages of several topics in one pass over the file (cached)."""
        wanted = [t for t in dict.fromkeys(topics) if t not in self._cache]
        if wanted:
            raw = self._linear if self._linear is not None else self._read_indexed(set(wanted))
            for topic in wanted:
                self._cache[topic] = [r for r in raw.values() if r.channel.topic == topic and r.messages]

    def _payloads(self, topic: str) -> list[tuple[int, bytes]]:
        """Raw messages of ``topic`` in log-time order (ties in file order)."""
        self.prefetch([topic])
        parts = self._cache[topic]
        if not parts:
            raise self._error(f"topic {topic!r} has no readable messages", topic=topic)
        schemas = {(p.schema.name if p.schema else "", p.channel.message_encoding) for p in parts}
        if len(schemas) > 1:
            raise self._error(f"topic {topic!r} mixes several types/encodings {sorted(schemas)}", topic=topic)
        messages = sorted((m for p in parts for m in p.messages), key=lambda m: (m[0], m[1]))
        return [(log_time, data) for log_time, _, data in messages]

    # ------------------------------------------------------------------ decoding and checks
