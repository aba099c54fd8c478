"""MCAP recordings: write episodes that ROS 2 tools and Foxglove open, and replay recordings.

* :func:`record_episode` / :func:`write_recording` write one episode, :class:`RecordMcap` a
  Gymnasium loop (:mod:`~fkn_bench.recordings.writer` documents topics, frames and conventions).
* :func:`load_episodes` / :func:`read_recording` turn a recording (fkn-bench, Astrobee simulation,
  any ROS 1 / ROS 2 / Foxglove JSON pose topic) into :class:`~fkn_bench.envs.Episodes`
  (:mod:`~fkn_bench.recordings.replay`); ``gym.make("AstrobeeReplay-v0", path=...)`` replays one.
* Bad files raise :class:`RecordingError` naming the file, topic and message, or are repaired
  when asked (:mod:`~fkn_bench.recordings.reader`).
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
from fkn_bench.recordings.replay import (
    ASTROBEE_TRUTH_PATTERN,
    RecordedTrajectory,
    ReplayReport,
    load_episodes,
    read_recording,
)
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
    "ASTROBEE_TRUTH_PATTERN", "DEFAULT_START_EPOCH_NS", "McapRecording", "PoseSeries",
    "RecordMcap", "RecordedTrajectory", "RecordingError", "RecordingRepairWarning",
    "RecordingSummary", "RecordingTopics", "ReplayReport", "TopicInfo", "TopicNotFoundError",
    "TwistSeries", "list_topics", "load_episodes", "read_metadata", "read_recording",
    "record_episode", "ros_pose_covariance", "write_recording"
]
