"""Rendering of ``AstrobeeTumble-v0`` (issue 18): ``rgb_array`` frames that show the truth and the
estimate, ``RecordVideo``, and ``human`` on a machine without a display (``check_env`` with
frames: tests/envs/test_astrobee_tumble.py)."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import fkn_bench  # noqa: F401  (registers the environment)
from fkn_bench.geometry import quaternion as quat

ENV_ID = "AstrobeeTumble-v0"


def _frame_after(action_of_truth, seed: int = 2) -> np.ndarray:
    env = gym.make(ENV_ID, render_mode="rgb_array", expose_truth=True, n_steps=40)
    _, info = env.reset(seed=seed)
    for _ in range(5):
        _, _, _, _, info = env.step(action_of_truth(info["truth"]))
    return env.render()


def test_frames_show_the_estimate_and_move_with_it() -> None:
    env = gym.make(ENV_ID, render_mode="rgb_array")
    assert env.metadata["render_fps"] == 10 and "rgb_array" in env.metadata["render_modes"]
    with pytest.raises(gym.error.ResetNeeded):  # Gymnasium's order enforcing
        env.render()
    env.reset(seed=0)
    first = env.render()
    assert first.dtype == np.uint8 and first.ndim == 3 and first.shape[2] == 3 and first.shape[0] % 16 == 0
    assert len(np.unique(first.reshape(-1, 3), axis=0)) > 50 and first.std() > 10  # not blank

    turned = quat.from_rotation_vector(np.array([0.0, 0.0, np.pi / 2]))
    exact = _frame_after(lambda truth: truth)
    same = _frame_after(lambda truth: truth)
    rotated = _frame_after(lambda truth: np.concatenate([quat.multiply(turned, truth[:4]), truth[4:]]))
    assert np.array_equal(exact, same)  # deterministic
    changed = np.any(exact != rotated, axis=2)
    assert changed.mean() > 0.002  # the estimate's axes (and its error's text and trace) moved
    rows, cols = np.nonzero(changed[: exact.shape[0] * 3 // 4, : exact.shape[1] // 2])
    assert len(rows) > 100  # ... in the attitude panel itself, not only in the text


def test_human_mode_without_a_display_warns_once_and_draws_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MPLBACKEND", "agg")
    with pytest.warns(RuntimeWarning, match="render_mode='human' has no window .* Use render_mode='rgb_array'"):
        env = gym.make(ENV_ID, render_mode="human", n_steps=20)
    env.reset(seed=0)
    assert env.step(np.array([1.0] + [0.0] * 12))[3] is False and env.render() is None
    env.close()


def test_record_video_writes_a_video(tmp_path: Path) -> None:
    pytest.importorskip("moviepy", reason="RecordVideo needs the video extra: pip install 'fkn-bench[video]'")
    from gymnasium.wrappers import RecordVideo

    env = RecordVideo(gym.make(ENV_ID, render_mode="rgb_array", expose_truth=True, n_steps=20), str(tmp_path),
                      episode_trigger=lambda episode: True, disable_logger=True)
    _, info = env.reset(seed=1)
    truncated = False
    while not truncated:
        _, _, _, truncated, info = env.step(info["truth"])
    env.close()
    videos = list(tmp_path.glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 1000
