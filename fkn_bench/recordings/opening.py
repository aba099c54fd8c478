"""Open any supported recording file with the reader that fits it.

:func:`open_recording` is the one entry point for code that reads recordings (the replay of
:mod:`fkn_bench.envs.replay`, the CLI, external-estimate scoring): it returns a
:class:`~fkn_bench.recordings.base.Recording` — ``path``, ``repairs``, ``notes``, ``topics()``,
``describe_topics()``, ``metadata()``, ``require_topic(topic, role)``, ``prefetch(topics)``,
``read_poses(topic, ...)`` and ``read_twists(topic, ...)`` — whatever the file format:

* MCAP (``.mcap``; ROS 2 CDR, ROS 1 or Foxglove JSON messages; a ROS 2 bag's ``.mcap`` storage
  file too): :class:`~fkn_bench.recordings.reader.McapRecording`;
* a ROS 1 bag (``.bag``), a ROS 2 bag directory (``metadata.yaml`` with ``.db3`` or ``.mcap``
  storage; or that ``metadata.yaml``) or a bare ROS 2 sqlite3 file (``.db3``):
  :class:`~fkn_bench.recordings.bags.BagRecording` (``rosbags``).

The format is told by the file's first bytes (a directory is a ROS 2 bag), not by its name.
"""

from __future__ import annotations

from pathlib import Path

from fkn_bench.recordings.bags import ROS1_BAG_MAGIC, SQLITE_MAGIC, BagRecording
from fkn_bench.recordings.base import Recording, RecordingError, TopicInfo
from fkn_bench.recordings.reader import McapRecording

__all__ = ["open_recording", "read_metadata", "list_topics"]


def open_recording(path: str | Path, *, repair: bool = False) -> Recording:
    """The reader of the recording at ``path`` (module docstring).

    Args:
        path: an MCAP file, a ROS 1 bag, a ROS 2 bag directory (or its ``metadata.yaml``) or a
            ROS 2 ``.db3`` file.
        repair: apply the documented repairs instead of raising
            (:mod:`fkn_bench.recordings.base`, :mod:`fkn_bench.recordings.reader`).

    Raises:
        RecordingError: the file is missing, empty, damaged (and not repaired) or of another format.
    """
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"recording not found: {path}", path=path)
    if path.is_dir() or path.name == "metadata.yaml":
        return BagRecording(path, repair=repair)
    with path.open("rb") as fh:
        head = fh.read(16)
    if head.startswith((ROS1_BAG_MAGIC, SQLITE_MAGIC)):
        return BagRecording(path, repair=repair)
    return McapRecording(path, repair=repair)  # MCAP, or its errors (empty, truncated, not MCAP)


def read_metadata(path: str | Path) -> dict[str, dict[str, str]]:
    """Metadata records of a recording (see :func:`open_recording`)."""
    return open_recording(path).metadata()


def list_topics(path: str | Path) -> dict[str, TopicInfo]:
    """Topics of a recording with types, encodings and message counts."""
    return open_recording(path).topics()
