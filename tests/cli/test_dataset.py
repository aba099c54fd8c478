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
    assert on_dataset[0]["non_finite_runs"] == 0  # (issue 34: counted in --json)
    assert main(["dataset", "--scenario", "ds1", "--seeds", "2", "--split", "test", "--out", str(tmp_path)]) == 2
    assert "exists" in capsys.readouterr().err


def _one_error(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("fkn-bench dataset: error: "), err
    return err


def test_a_full_disk_is_one_line_before_any_work(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 34, finding 4: on a 2 MB file system ``dataset`` segfaulted (exit 139) and left 2 MB
    of scratch; now the free space is checked against the dataset's estimated size first."""
    import collections
    import shutil

    usage = collections.namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda _: usage(2_000_000, 0, 2_000_000))
    out = tmp_path / "tiny"
    assert main(["dataset", "--scenario", "ds1", "--seeds", "2", "--out", str(out)]) == 2
    err = _one_error(capsys)
    assert "no space left on the device to write the dataset fkn-bench/ds1-full-v0" in err
    assert "(2 MB free, about 10.8 MB needed)" in err
    assert [p.name for p in out.iterdir()] == [".fkn-bench.lock"]


@pytest.mark.parametrize("dataset_id", ["mydata", "../escaped-v0", "ABSOLUTE/escaped-v0"])
def test_a_bad_dataset_id_is_a_named_error_before_any_directory(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                dataset_id: str) -> None:
    """Issue 34, finding 7: ``--dataset-id mydata`` was a minari traceback; ``..`` and absolute
    ids made directories outside --out first."""
    dataset_id = dataset_id.replace("ABSOLUTE", str(tmp_path / "absolute"))
    assert main(["dataset", "--out", str(tmp_path / "out"), "--dataset-id", dataset_id]) == 2
    assert "is not a Minari dataset id: it must be NAME-vN or NAMESPACE/NAME-vN" in _one_error(capsys)
    assert list(tmp_path.iterdir()) == []


def test_a_dataset_directory_in_use_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 34, finding 6: two ``dataset`` runs of one id both reported success."""
    from fkn_bench.io import directory_lock

    with directory_lock(tmp_path):
        assert main(["dataset", "--seeds", "2", "--out", str(tmp_path)]) == 2
    assert "in use by another fkn-bench process writing the dataset fkn-bench/ds1-full-v0" in _one_error(capsys)
