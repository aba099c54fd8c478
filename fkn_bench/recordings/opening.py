"""Open any supported recording file with the reader that fits it.

:func:`open_recording` is the one entry point for code that reads recordings (the replay of
:mod:`fkn_bench.envs.replay`, the CLI, external-estimate scoring): it returns an object with the
interface of :class:`~fkn_bench.recordings.reader.McapRecording` — ``path``, ``repairs``,
``notes``, ``topics()``, ``describe_topics()``, ``metadata()``, ``require_topic(topic, role)``,
``prefetch(topics)``, ``read_poses(topic, ...)`` and ``read_twists(topic, ...)`` — whatever the
file format.
"""

from __future__ import annotations

from pathlib import Path

from fkn_bench.recordings.reader import McapRecording

__all__ = ["open_recording"]


def open_recording(path: str | Path, *, repair: bool = False) -> McapRecording:
    """The reader of the recording at ``path``.

    Args:
        path: an MCAP file.
        repair: apply the documented repairs instead of raising
            (:mod:`fkn_bench.recordings.reader`).

    Raises:
        RecordingError: the file is missing, empty, damaged (and not repaired) or of another format.
    """
    return McapRecording(path, repair=repair)
