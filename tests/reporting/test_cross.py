"""The cross-scenario table: one row per estimator and training family, one column per scenario."""

from __future__ import annotations

from fkn_bench.reporting.cross import cross_table


def test_cross_table_rows_columns_and_missing_cells() -> None:
    scores = {("direct-tuned-ekf", "ds1", "ds2"): (0.0123456, 0.0), ("direct-tuned-ekf", "tumble", "ds1"): (0.5, 0.25)}
    table = cross_table(scores, ["ds2", "ds1"])
    assert table.header == ["estimator", "trained on", "ds2", "ds1"]
    assert table.rows == [["direct-tuned-ekf", "ds1", "0.0123", "–"], ["direct-tuned-ekf", "tumble", "–", "0.5000 (25% div.)"]]
