"""MCAP recordings, the file format: write episodes that ROS 2 tools and Foxglove open, and read
the pose and twist topics of a recording. Nothing here simulates or scores: the package imports
only the ground floor (geometry, io, types, provenance, the package root).

* :func:`record_episode` / :func:`write_recording` write one episode, :class:`RecordMcap` a
  Gymnasium loop (:mod:`~fkn_bench.recordings.writer` documents topics, frames and conventions).
* :func:`open_recording` opens a recording with the reader that fits its format;
  :class:`McapRecording` reads a recording's topics (fkn-bench, Astrobee simulation, any ROS 1 /
  ROS 2 / Foxglove JSON pose topic) as time series; bad files raise :class:`RecordingError`
  naming the file, topic and message, or are repaired when asked (:mod:`~fkn_bench.recordings.reader`).
* Replaying a recording as :class:`~fkn_bench.envs.Episodes` (``load_episodes``,
  ``read_recording``) is :mod:`fkn_bench.envs.replay`'s; ``gym.make("AstrobeeReplay-v0", path=...)``
  replays one in Gymnasium.
"""

from fkn_bench.recordings.reader import (
    McapRecording,
    PoseSeries,
    RecordingError,
    RecordingRepairWarning,
    TopicInfo,
    TopicNotFoundError,
    TwistSeries,
    list_topics,
    read_metadata,
)
from fkn_bench.recordings.opening import open_recording
from fkn_bench.recordings.wrapper import RecordMcap
from fkn_bench.recordings.writer import (
    DEFAULT_START_EPOCH_NS,
    RecordingSummary,
    RecordingTopics,
    record_episode,
    ros_pose_covariance,
    write_recording,
)

__all__ = [
    "DEFAULT_START_EPOCH_NS", "McapRecording", "PoseSeries", "RecordMcap", "RecordingError",
    "RecordingRepairWarning", "RecordingSummary", "RecordingTopics", "TopicInfo", "TopicNotFoundError",
    "TwistSeries", "list_topics", "open_recording", "read_metadata", "record_episode", "ros_pose_covariance", "write_recording"
]
