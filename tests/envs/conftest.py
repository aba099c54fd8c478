"""Fixtures of the environment tests: the recording tests' short recorded episode and MCAP file
builders (:mod:`tests.recordings.conftest`), which the replay tests (``test_replay.py``) read back."""

from __future__ import annotations

from tests.recordings.conftest import make_mcap, recorded, short_episode, tools

__all__ = ["make_mcap", "recorded", "short_episode", "tools"]
