"""Read pose and twist topics from ROS 1 bags and ROS 2 bags, through ``rosbags``.

:class:`BagRecording` reads, with ``rosbags.highlevel.AnyReader`` (Ternaris' pure-Python rosbag
library):

* a ROS 1 bag (``.bag``, format 2.0, compressed or not; messages in the ROS 1 wire format);
* a ROS 2 bag: its directory (``metadata.yaml`` and its ``.db3`` or ``.mcap`` storage files, the
  ``metadata.yaml`` itself names the same bag), or one bare sqlite3 storage file (``.db3``);
  messages in CDR. (A bare ``.mcap`` file is read by :class:`~fkn_bench.recordings.reader.McapRecording`.)

The messages are decoded by ``rosbags``' typestores of the standard messages
(:func:`~fkn_bench.recordings.codecs.decode_stamped`); their checks and repairs are
:class:`~fkn_bench.recordings.base.Recording`'s (:mod:`fkn_bench.recordings.base`). The log time
of a message is the time the bag recorder received it. Bags carry no fkn-bench metadata: a ROS 2
bag's ``custom_data`` (``metadata.yaml``) is the metadata record ``rosbag2.custom_data``.

A bag that ``rosbags`` cannot open (truncated, not indexed, damaged index, corrupt chunk,
unknown storage or compression) raises :class:`~fkn_bench.recordings.base.RecordingError`: one
line naming the file and what ``rosbags`` said; ``repair`` cannot help there (a ROS 1 bag is
repaired with ``rosbag reindex``). A bag that opens but fails while its messages are read keeps,
with ``repair=True``, the messages read before the damage.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from rosbags.highlevel import AnyReader
from rosbags.interfaces import Connection, ConnectionExtRosbag2
from rosbags.typesys import Stores, get_typestore

from fkn_bench.recordings.base import Recording, RecordingError, TopicInfo, describe_exception
from fkn_bench.wording import option

__all__ = ["BagRecording", "ROS1_BAG_MAGIC", "SQLITE_MAGIC"]

ROS1_BAG_MAGIC = b"#ROSBAG"
SQLITE_MAGIC = b"SQLite format 3"
_FORMATS = {"ros1msg": "ros1msg", "ros2msg": "ros2msg", "ros2idl": "ros2idl"}


def _one_line(text: str) -> str:
    return " ".join(text.split())


class BagRecording(Recording):
    """A ROS 1 or ROS 2 bag opened for reading pose topics (module docstring).

    Opening reads the bag's topics (and closes it again); :meth:`prefetch` reads the messages of
    the topics asked for in one pass.

    Args:
        path: a ``.bag`` file, a ROS 2 bag directory (or its ``metadata.yaml``) or a ``.db3`` file.
        repair: keep the messages read before a failure while reading messages.

    Raises:
        RecordingError: the file is missing or empty, or ``rosbags`` cannot open it.
    """

    def __init__(self, path: str | Path, *, repair: bool = False) -> None:
        path = Path(path)
        if path.name == "metadata.yaml" and path.is_file():
            path = path.parent
        super().__init__(path, repair=repair)
        self._check_path()
        self._cache: dict[str, list[tuple[int, bytes]]] = {}
        self._metadata: dict[str, dict[str, str]] = {}
        with self._open() as reader:
            self._topics = self._describe(reader.connections)
            custom = getattr(getattr(reader.readers[0], "metadata", None), "custom", None) if self.is_ros2 else None
            if custom:
                self._metadata["rosbag2.custom_data"] = {str(k): str(v) for k, v in custom.items()}

    @property
    def is_ros2(self) -> bool:
        return self.path.suffix != ".bag"

    @property
    def kind(self) -> str:
        """``"ROS 1 bag"`` or ``"ROS 2 bag"``."""
        return "ROS 2 bag" if self.is_ros2 else "ROS 1 bag"

    # ------------------------------------------------------------------ opening
    def _check_path(self) -> None:
        path = self.path
        if not path.exists():
            raise RecordingError(f"recording not found: {path}", path=path)
        if path.is_dir():
            if not (path / "metadata.yaml").is_file():
                raise self._error("is a directory without metadata.yaml, not a ROS 2 bag")
            return
        if path.stat().st_size == 0:
            raise self._error(f"the file is empty (0 bytes); it is not a {self.kind}")
        with path.open("rb") as fh:
            head = fh.read(16)
        for magic, what, suffix in ((ROS1_BAG_MAGIC, "a ROS 1 bag", ".bag"), (SQLITE_MAGIC, "a ROS 2 sqlite3 bag", ".db3")):
            if head.startswith(magic) and path.suffix != suffix:
                raise self._error(f"this is {what}; rosbags reads it only under a name ending in {suffix} (rename it)")

    @contextmanager
    def _open(self) -> Iterator[AnyReader]:
        """An open AnyReader of the bag, closed on leaving the context."""
        try:
            reader = AnyReader([self.path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
            reader.open()
        except Exception as exc:  # AnyReaderError, ReaderError, TypesysError, sqlite and OS errors
            raise self._error(f"rosbags cannot read this {self.kind}: {_one_line(describe_exception(exc))}") from None
        try:
            yield reader
        finally:
            reader.close()

    def _describe(self, connections: Iterable[Connection]) -> dict[str, TopicInfo]:
        """One :class:`TopicInfo` per topic (counts summed over its connections)."""
        out: dict[str, TopicInfo] = {}
        for c in connections:
            encoding = c.ext.serialization_format if isinstance(c.ext, ConnectionExtRosbag2) else "ros1"
            schema_encoding = _FORMATS.get(c.msgdef.format.name.lower(), "") if c.msgdef.data else ""
            if not self.is_ros2 and schema_encoding:
                schema_encoding = "ros1msg"
            previous = out.get(c.topic)
            count = c.msgcount + (previous.message_count or 0 if previous else 0)
            msgtype = c.msgtype if previous is None or previous.schema_name == c.msgtype else "(several types)"
            out[c.topic] = TopicInfo(c.topic, msgtype, schema_encoding, encoding, count)
        return out

    # ------------------------------------------------------------------ the Recording interface
    def topics(self) -> dict[str, TopicInfo]:
        return dict(self._topics)

    def metadata(self) -> dict[str, dict[str, str]]:
        return {name: dict(record) for name, record in self._metadata.items()}

    def prefetch(self, topics: Iterable[str]) -> None:
        wanted = [t for t in dict.fromkeys(topics) if t not in self._cache and t in self._topics]
        if not wanted:
            return
        read: dict[str, list[tuple[int, int, bytes]]] = {t: [] for t in wanted}
        with self._open() as reader:
            connections = [c for c in reader.connections if c.topic in read]
            position = 0
            try:
                for connection, timestamp, data in reader.messages(connections=connections):
                    read[connection.topic].append((timestamp, position, bytes(data)))
                    position += 1
            except Exception as exc:
                problem = f"reading its messages failed after {position} ({_one_line(describe_exception(exc))})"
                self._repair(
                    f"{problem}. Pass {option('repair')} to use the messages read before the damage",
                    f"{problem}; used the messages read before the damage",
                )
        for topic, messages in read.items():
            messages.sort(key=lambda m: (m[0], m[1]))
            self._cache[topic] = [(log_time, data) for log_time, _, data in messages]

    def _payloads(self, topic: str) -> list[tuple[int, bytes]]:
        info = self._topics[topic]
        if info.schema_name == "(several types)":
            raise self._error(f"topic {topic!r} mixes several message types", topic=topic)
        self.prefetch([topic])
        if not self._cache[topic]:
            raise self._error(f"topic {topic!r} has no readable messages", topic=topic)
        return self._cache[topic]

