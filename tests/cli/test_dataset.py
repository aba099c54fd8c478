"""``fkn-bench dataset`` and ``fkn-bench run --dataset``: an estimator scores on the dataset exactly
as on the scenario it was written from."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fkn_bench.cli import main

TIMING = ("us_per_step", "us_per_step_batched", "us_per_step_online", "peak_memory_mib")


def test_run_on_a_dataset_scores_as_the_direct_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["dataset", "--scenario", "ds1", "--seeds", "2", "--split", "test", "--out", str(tmp_path)]) == 0
    written = tmp_path / "fkn-bench" / "ds1-test-v0"
    assert f"fkn-bench run --dataset {written}" in capsys.readouterr().err
    common = ["--estimator", "manual-ekf", "--no-progress", "--json"]
    assert main(["run", "--dataset", str(written), *common]) == 0
    on_dataset = json.loads(capsys.readouterr().out)["results"]
    assert main(["run", "--scenario", "ds1", "--seeds", "2", *common]) == 0
    direct = json.loads(capsys.readouterr().out)["results"]
    assert len(on_dataset) == len(direct) == 1
    strip = lambda r: {k: v for k, v in r.items() if k not in TIMING}  # noqa: E731
    assert strip(on_dataset[0]) == strip(direct[0]) and on_dataset[0]["runs"] == 2
    assert main(["dataset", "--scenario", "ds1", "--seeds", "2", "--split", "test", "--out", str(tmp_path)]) == 2
    assert "exists" in capsys.readouterr().err
