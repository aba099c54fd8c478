"""record(): generate an episode, run an estimator on it and write both to MCAP."""

from __future__ import annotations

from fkn_bench.exporters.recording import record
from fkn_bench.recordings import read_metadata


def test_record_generates_estimates_and_windows(tmp_path) -> None:
    summary = record(tmp_path / "r.mcap", scenario="ds1", estimator="manual-ekf", seed=1, n_steps=120)
    assert summary.n_steps == 120
    assert summary.message_counts["/fkn_bench/measured_pose"] == 12
    assert {"generate_seconds", "estimate_seconds"} <= set(summary.timings)
    assert read_metadata(summary.path)["fkn_bench.episode"]["split"] == "full[:120]"
    none = record(tmp_path / "n.mcap", estimator=None, n_steps=50)
    assert "/loc/pose" not in none.message_counts
    assert "fkn_bench.estimator" not in read_metadata(none.path)
