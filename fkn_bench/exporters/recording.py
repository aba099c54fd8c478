"""Record an episode with an estimator: generate it, run the estimator, write the MCAP file.

The file format (topics, conventions, metadata) is :mod:`fkn_bench.recordings.writer`'s; this
module only produces what it writes (``fkn-bench record`` calls :func:`record`).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from fkn_bench.envs import generate_episodes
from fkn_bench.estimators import Estimator, load_estimator, make_estimator
from fkn_bench.recordings import RecordingSummary, record_episode
from fkn_bench.scenarios import get_scenario

__all__ = ["record"]


def record(
    path: str | Path,
    *,
    scenario: Any = "ds1",
    estimator: Any = "manual-ekf",
    seed: int = 0,
    split: str = "full",
    n_steps: int | None = None,
    estimator_options: Mapping[str, Any] | None = None,
    **options: Any,
) -> RecordingSummary:
    """Generate episode ``seed`` of ``scenario``, run ``estimator`` on it (batch) and record both.

    Args:
        path: output ``.mcap`` file.
        scenario: registered name or :class:`~fkn_bench.scenarios.Scenario`.
        estimator: registered name, an :class:`~fkn_bench.estimators.Estimator`, the path of a
            saved estimator (``.json``), or None to record truth and measurements only.
        seed: episode seed.
        split: ``full`` (default), ``train``, ``val`` or ``test``.
        n_steps: record only the first ``n_steps`` steps of the split.
        estimator_options: keyword options for the estimator factory.
        options: :func:`~fkn_bench.recordings.record_episode` /
            :func:`~fkn_bench.recordings.write_recording` options.

    Returns:
        The :class:`~fkn_bench.recordings.RecordingSummary`, with ``timings``
        ``generate_seconds`` and ``estimate_seconds`` added.
    """
    sc = get_scenario(scenario)
    started = time.perf_counter()
    episodes = generate_episodes(sc, [int(seed)], split=split)
    if n_steps is not None:
        if int(n_steps) < 1:
            raise ValueError(f"n_steps must be >= 1 (got {n_steps})")
        episodes = episodes.window(0, int(n_steps))
    generated = time.perf_counter()
    est_obj = estimates = None
    if estimator is not None:
        if isinstance(estimator, Estimator):
            est_obj = estimator
        elif isinstance(estimator, (str, Path)) and str(estimator).endswith(".json") and Path(estimator).is_file():
            est_obj = load_estimator(estimator)
        else:
            est_obj = make_estimator(str(estimator), scenario=sc, **dict(estimator_options or {}))
        estimates = est_obj.estimate(episodes.measurements, episodes.valid, sc.dt)
    estimated = time.perf_counter()
    split_label = split if n_steps is None else f"{split}[:{int(n_steps)}]"
    summary = record_episode(path, episodes, estimates, estimator=est_obj, split=split_label, **options)
    summary.timings.update({"generate_seconds": generated - started, "estimate_seconds": estimated - generated})
    return summary
