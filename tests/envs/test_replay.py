"""Replay: recordings back to Episodes (bit-exact for fkn-bench recordings, same metrics as a
direct run), Astrobee topics, resampling by slerp, twist sources and frames, ROS 1, Foxglove
JSON, synthesised versus recorded measurements."""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest

from fkn_bench.envs import generate_episodes
from fkn_bench.estimators import make_estimator
from fkn_bench.envs.replay import finite_difference_twist, load_episodes, read_recording
from fkn_bench.geometry import quaternion as quat
from fkn_bench.recordings import RecordingError, TopicNotFoundError
from fkn_bench.types import STATE_GROUPS


def _rmse(truth: np.ndarray, means: np.ndarray) -> dict[str, float]:
    """Per-component RMSE of the means against the truth (attitude sign-aligned first)."""
    est = means.copy()
    est[..., :4] = quat.align_sign(est[..., :4], truth[..., :4])
    err = est - truth
    return {name: float(np.sqrt(np.mean(err[..., s] ** 2))) for name, s in STATE_GROUPS.items()}


def test_replay_of_a_recording_is_bit_exact(recorded) -> None:
    episodes = recorded.episodes
    replayed = load_episodes(recorded.path, seed=3)
    assert replayed.truth.shape == episodes.truth.shape
    # exact in this file: MCAP stores float64 losslessly, and measurements are re-synthesised from
    # the read-back truth with the same seeded draws and arithmetic (same computation twice); the
    # replayed estimates and RMSEs are then the same computation on bit-identical inputs
    assert np.array_equal(replayed.truth, episodes.truth)  # pose and recorded twist, bit for bit
    assert np.array_equal(replayed.times, episodes.times)
    # synthesised measurements use the stored scenario's noise model: same seed, same data
    assert np.array_equal(replayed.valid, episodes.valid)
    assert np.array_equal(replayed.measurements, episodes.measurements, equal_nan=True)
    assert replayed.scenario.dt == episodes.scenario.dt
    assert replayed.scenario.n_steps == episodes.n_steps
    assert replayed.scenario.name == "replay-episode"
    assert replayed.seeds == (3,) and replayed.start == 0


def test_recorded_measurements_are_used_as_is(recorded) -> None:
    trajectory = read_recording(recorded.path, measurement_topic="/fkn_bench/measured_pose")
    for seed in (0, 9):
        replayed = trajectory.episodes(seed)
        assert np.array_equal(replayed.valid, recorded.episodes.valid)
        assert np.array_equal(replayed.measurements, recorded.episodes.measurements, equal_nan=True)
    assert trajectory.report.measurement_source == "topic /fkn_bench/measured_pose"
    assert trajectory.report.twist_source == "topic /loc/truth/twist"
    assert trajectory.report.interpolated_steps == 0
    assert trajectory.report.repairs == ()


def test_synthesised_measurements_depend_on_the_seed(recorded) -> None:
    trajectory = read_recording(recorded.path)
    a, b = trajectory.episodes(0), trajectory.episodes(1)
    assert np.array_equal(a.truth, b.truth)
    assert not np.array_equal(a.measurements, b.measurements, equal_nan=True)
    assert trajectory.report.measurement_source.startswith("synthesised")


def test_replay_gives_the_same_metrics_as_a_direct_run(recorded) -> None:
    episodes = recorded.episodes
    direct = recorded.estimates
    replayed = load_episodes(recorded.path, measurement_topic="/fkn_bench/measured_pose")
    estimator = make_estimator("manual-ekf", scenario=replayed.scenario)
    again = estimator.estimate(replayed.measurements, replayed.valid, replayed.scenario.dt)
    assert _rmse(replayed.truth, again.means) == _rmse(episodes.truth, direct.means)
    assert np.array_equal(again.means, direct.means)


def test_the_foxglove_channel_replays_the_same_truth_pose(recorded) -> None:
    fox = read_recording(recorded.path, truth_topic="/foxglove/truth_pose")
    assert fox.report.truth_type == "foxglove.PoseInFrame"
    assert np.array_equal(fox.truth[:, :7], recorded.episodes.truth[0, :, :7])
    assert fox.report.twist_source == "finite differences"


# ---------------------------------------------------------------------------- Astrobee-style files
def _astrobee_file(tools, make_mcap, name="astrobee.mcap", robot="/honey", n=126, zero_stamps=False, encoding="cdr"):
    """2 s of Astrobee-style ground truth at 62.5 Hz (16 ms): pose and world-frame twist."""
    t, states = tools.forced_rotation(n, 0.016)
    stamps = tools.EPOCH_NS + np.round(t * 1e9).astype(np.int64)
    header = np.zeros_like(stamps) if zero_stamps else stamps
    channels = [
        tools.pose_channel(f"{robot}/loc/truth/pose", header, states[:, :7], log_ns=stamps, encoding=encoding),
        tools.twist_channel(f"{robot}/loc/truth/twist", header, states[:, 7:10], states[:, 10:13], log_ns=stamps, encoding=encoding),
        tools.pose_channel(f"{robot}/loc/pose", stamps, states[:, :7], encoding=encoding),
    ]
    return make_mcap(name, channels, profile="ros2" if encoding == "cdr" else "ros1"), t, states


def test_astrobee_truth_topic_found_without_arguments(tools, make_mcap) -> None:
    path, t, states = _astrobee_file(tools, make_mcap)
    trajectory = read_recording(path, dt="native")
    report = trajectory.report
    assert report.truth_topic == "/honey/loc/truth/pose"
    assert report.truth_rate_hz == pytest.approx(62.5)
    assert report.twist_source == "topic /honey/loc/truth/twist"
    assert trajectory.scenario.dt == 0.016
    assert np.array_equal(trajectory.truth, states)
    # at the default scenario rate (ds1: 0.1 s) the truth is resampled
    coarse = read_recording(path)
    assert coarse.scenario.dt == 0.1 and coarse.n_steps == 21
    assert coarse.report.interpolated_steps > 0


def test_zero_header_stamps_fall_back_to_log_time(tools, make_mcap) -> None:
    path, _, states = _astrobee_file(tools, make_mcap, zero_stamps=True)
    trajectory = read_recording(path, dt="native")
    assert trajectory.report.time_source == "log"
    assert any("every header stamp is zero" in note for note in trajectory.report.notes)
    assert np.array_equal(trajectory.truth, states)
    with pytest.raises(RecordingError, match="every header stamp is zero"):
        read_recording(path, time_source="header")


def test_ros1_recording(tools, make_mcap) -> None:
    path, _, states = _astrobee_file(tools, make_mcap, robot="", encoding="ros1")
    trajectory = read_recording(path, dt="native")
    assert trajectory.report.truth_topic == "/loc/truth/pose"
    assert trajectory.report.truth_type == "geometry_msgs/PoseStamped"
    assert np.array_equal(trajectory.truth, states)


def test_several_robots_need_a_truth_topic(tools, make_mcap) -> None:
    t, states = tools.forced_rotation(30, 0.1)
    stamps = tools.EPOCH_NS + np.round(t * 1e9).astype(np.int64)
    path = make_mcap(
        "two.mcap",
        [tools.pose_channel(f"/{r}/loc/truth/pose", stamps, states[:, :7]) for r in ("honey", "bumble")],
    )
    with pytest.raises(RecordingError, match="several ground-truth topics.*truth_topic"):
        read_recording(path)
    assert read_recording(path, truth_topic="/bumble/loc/truth/pose").report.truth_topic == "/bumble/loc/truth/pose"


def test_missing_topic_lists_topics_and_types(tools, make_mcap) -> None:
    path, _, _ = _astrobee_file(tools, make_mcap)
    with pytest.raises(TopicNotFoundError) as info:
        read_recording(path, truth_topic="/nope")
    message = str(info.value)
    assert str(path) in message and "'/nope' not found" in message
    assert re.search(r"\n  /honey/loc/truth/pose +geometry_msgs/msg/PoseStamped \(cdr, 126 messages\)", message)
    t, states = tools.forced_rotation(30, 0.1)
    other = make_mcap("other.mcap", [tools.pose_channel("/pose", t * 1e9 + tools.EPOCH_NS, states[:, :7])])
    with pytest.raises(TopicNotFoundError, match=r"none named <robot>/loc/truth/pose.*\n.*/pose"):
        read_recording(other)
    with pytest.raises(TopicNotFoundError, match="measurement topic '/meas' not found"):
        read_recording(path, measurement_topic="/meas")


def test_resampling_uses_slerp_between_neighbours(tools, make_mcap) -> None:
    t, states = tools.forced_rotation(101, 0.016, omega=(0.5, -0.4, 0.9))
    stamps = tools.EPOCH_NS + np.round(t * 1e9).astype(np.int64)
    path = make_mcap("fast.mcap", [tools.pose_channel("/loc/truth/pose", stamps, states[:, :7])])
    trajectory = read_recording(path, dt=0.1)  # grid 0, 0.1, ... 1.6 s: mostly between messages
    grid_t = trajectory.times
    for k, tk in enumerate(grid_t):
        i = int(np.searchsorted(t, tk, side="right") - 1)
        i = min(i, len(t) - 2)
        frac = (tk - t[i]) / (t[i + 1] - t[i])
        expected = quat.slerp(states[i, :4], states[i + 1, :4], frac)
        assert np.allclose(trajectory.truth[k, :4], expected, atol=1e-12)
        assert np.allclose(trajectory.truth[k, 4:7], states[i, 4:7] + frac * (states[i + 1, 4:7] - states[i, 4:7]), atol=1e-12)
    # constant rotation: slerp is exact, so the resampled attitude is the true one
    exact = quat.multiply(quat.from_rotation_vector(grid_t[:, None] * np.array([0.5, -0.4, 0.9])), states[0, :4])
    assert np.max(quat.angle_between(trajectory.truth[:, :4], exact)) < 1e-9
    # finite-difference twist of the constant motion is exact to rounding
    assert trajectory.report.twist_source == "finite differences"
    assert np.allclose(trajectory.truth[:, 7:10], [0.5, -0.4, 0.9], atol=1e-9)
    assert np.allclose(trajectory.truth[:, 10:13], [0.01, -0.02, 0.03], atol=1e-9)


def test_finite_difference_twist_on_a_sign_flipping_sequence(tools) -> None:
    t, states = tools.forced_rotation(20, 0.1)
    q = states[:, :4].copy()
    q[::2] *= -1  # q and -q alternate: same attitudes
    stamps = (t * 1e9).astype(np.int64)
    twist = finite_difference_twist(stamps, np.concatenate([q, states[:, 4:7]], axis=1))
    assert np.allclose(twist[:, :3], states[:, 7:10], atol=1e-9)


def test_odometry_truth_with_body_frame_twist(tools, make_mcap) -> None:
    t, states = tools.forced_rotation(50, 0.1)
    stamps = tools.EPOCH_NS + np.round(t * 1e9).astype(np.int64)
    R_T = np.swapaxes(quat.rotation_matrix(states[:, :4]), -1, -2)
    w_body = np.einsum("nij,nj->ni", R_T, states[:, 7:10])
    v_body = np.einsum("nij,nj->ni", R_T, states[:, 10:13])
    cov = np.zeros((50, 36))
    extra = np.concatenate([cov, v_body, w_body, cov], axis=1)  # pose cov, twist linear, angular, cov
    path = make_mcap(
        "odom.mcap",
        [tools.pose_channel("/odom", stamps, states[:, :7], type_name="nav_msgs/Odometry", extra=extra,
                            frame_id="world", child_frame_id="body")],
    )
    trajectory = read_recording(path, truth_topic="/odom", dt="native")
    assert trajectory.report.twist_source == "odometry /odom"
    assert trajectory.report.twist_frame == "body"
    assert np.allclose(trajectory.truth, states, atol=1e-12)
    world = read_recording(path, truth_topic="/odom", dt="native", twist_frame="world")
    assert np.allclose(world.truth[:, 7:10], w_body)


def test_pose_with_covariance_measurements_snap_to_the_grid(tools, make_mcap) -> None:
    t, states = tools.forced_rotation(50, 0.1)
    stamps = tools.EPOCH_NS + np.round(t * 1e9).astype(np.int64)
    m_idx = np.arange(2, 50, 5)
    m_stamps = stamps[m_idx] + 20_000_000  # 20 ms late
    noisy = states[m_idx, :7].copy()
    noisy[:, 4:] += 0.1
    path = make_mcap(
        "meas.mcap",
        [
            tools.pose_channel("/loc/truth/pose", stamps, states[:, :7]),
            tools.pose_channel("/fix", m_stamps, noisy, type_name="geometry_msgs/PoseWithCovarianceStamped",
                               extra=np.zeros((len(m_idx), 36))),
        ],
    )
    episodes = load_episodes(path, measurement_topic="/fix")
    assert np.flatnonzero(episodes.valid[0]).tolist() == m_idx.tolist()
    assert np.array_equal(episodes.measurements[0, m_idx], noisy)
    trajectory = read_recording(path, measurement_topic="/fix")
    assert any("nearest step (up to 20 ms)" in note for note in trajectory.report.notes)


def test_options_are_checked(recorded) -> None:
    with pytest.raises(ValueError, match="dt must be"):
        read_recording(recorded.path, dt="fast")
    with pytest.raises(ValueError, match="dt must be a finite number"):
        read_recording(recorded.path, dt=-1)
    with pytest.raises(ValueError, match="twist_frame"):
        read_recording(recorded.path, twist_frame="up")
    with pytest.raises(ValueError, match="time_source"):
        read_recording(recorded.path, time_source="gps")
    with pytest.raises(RecordingError, match="too few for a scenario"):
        read_recording(recorded.path, dt=10.0)  # 3 steps
    short = read_recording(recorded.path, dt=3.0)  # 10 steps: too few for 80/10/10
    assert short.scenario.split_bounds()["val"] == (6, 8)
    assert any("too few for the split" in note for note in short.report.notes)
    with pytest.raises(ValueError, match="seed"):
        read_recording(recorded.path).episodes(-1)


def test_explicit_scenario_and_no_twist_topic(recorded) -> None:
    trajectory = read_recording(recorded.path, scenario="ds1-noise5x", twist_topic=None)
    assert trajectory.scenario.noise_scale == 5.0
    assert trajectory.report.twist_source == "finite differences"
    direct = generate_episodes(recorded.episodes.scenario.replace(noise_scale=5.0), [3])
    assert np.array_equal(trajectory.episodes(3).measurements, direct.measurements, equal_nan=True)
    assert np.allclose(trajectory.truth[:, 7:], recorded.episodes.truth[0, :, 7:], atol=1e-9)


def test_no_warnings_for_clean_files(recorded) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_recording(recorded.path)


@pytest.mark.parametrize("layout", ["chunked, no summary", "unchunked, no summary", "indexed, no statistics"])
def test_files_without_summary_chunks_or_statistics(tools, tmp_path, layout: str) -> None:
    """Valid MCAP files without an index (read front to back) or without statistics replay the same."""
    from mcap.writer import IndexType, Writer

    t, states = tools.forced_rotation(30, 0.1)
    stamps = tools.EPOCH_NS + np.round(t * 1e9).astype(np.int64)
    spec = tools.pose_channel("/loc/truth/pose", stamps, states[:, :7])
    path = tmp_path / "plain.mcap"
    if layout == "indexed, no statistics":
        options = dict(use_statistics=False)
    else:
        options = dict(index_types=IndexType.NONE, repeat_channels=False, repeat_schemas=False,
                       use_chunking=layout.startswith("chunked"), use_statistics=False, use_summary_offsets=False)
    with open(path, "wb") as fh:
        writer = Writer(fh, **options)
        writer.start(profile="ros2")
        schema = writer.register_schema(spec.schema_name, spec.schema_encoding, spec.schema_data)
        channel = writer.register_channel(spec.topic, spec.message_encoding, schema)
        for log, data in spec.messages:
            writer.add_message(channel, log_time=log, data=data, publish_time=log)
        writer.add_metadata("note", {"k": "v"})
        writer.finish()
    trajectory = read_recording(path, dt="native")
    assert np.array_equal(trajectory.truth[:, :7], states[:, :7])
    assert trajectory.report.repairs == ()
    assert trajectory.report.metadata["note"] == {"k": "v"}
