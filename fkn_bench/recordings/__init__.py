"""Recordings, the file formats: write episodes as MCAP files that ROS 2 tools and Foxglove open,
and read the pose and twist topics of MCAP files and ROS 1 / ROS 2 bags. Nothing here simulates or scores: the package imports
only the ground floor (geometry, io, types, provenance, the package root).

* :func:`record_episode` / :func:`write_recording` write one episode, :class:`RecordMcap` a
  Gymnasium loop (:mod:`~fkn_bench.recordings.writer` documents topics, frames and conventions).
* :func:`open_recording` opens a recording with the reader that fits it: :class:`McapRecording`
  (MCAP) or :class:`BagRecording` (ROS 1 ``.bag``, ROS 2 bag directories and ``.db3``, through
  ``rosbags``); both read a recording's topics (fkn-bench, Astrobee, any ROS 1 / ROS 2 / Foxglove
  JSON pose topic) as time series, pose covariances included; bad files raise
  :class:`RecordingError` naming the file, topic and message, or are repaired when asked
  (:mod:`~fkn_bench.recordings.base`, :mod:`~fkn_bench.recordings.reader`).
* Replaying a recording as :class:`~fkn_bench.envs.Episodes` (``load_episodes``,
  ``read_recording``) is :mod:`fkn_bench.envs.replay`'s; ``gym.make("AstrobeeReplay-v0", path=...)``
  replays one in Gymnasium.
"""

from fkn_bench.recordings.bags import BagRecording
from fkn_bench.recordings.base import (
    PoseSeries,
    Recording,
    RecordingError,
    RecordingRepairWarning,
    TopicInfo,
    TopicNotFoundError,
    TwistSeries,
)
from fkn_bench.recordings.opening import list_topics, open_recording, read_metadata
from fkn_bench.recordings.reader import McapRecording
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
    "BagRecording", "DEFAULT_START_EPOCH_NS", "McapRecording", "PoseSeries", "RecordMcap", "RecordingError",
    "Recording", "RecordingRepairWarning", "RecordingSummary", "RecordingTopics", "TopicInfo", "TopicNotFoundError",
    "TwistSeries", "list_topics", "open_recording", "read_metadata", "record_episode", "ros_pose_covariance", "write_recording"
]
