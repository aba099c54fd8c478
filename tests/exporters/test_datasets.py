"""Minari datasets (issue 18): what ``write_dataset`` stores is the environment's episodes bit for
bit, Minari reads it, and ``DatasetSource`` gives the harness the episodes a direct run uses."""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pytest

import fkn_bench  # noqa: F401  (registers the environment)
from fkn_bench.envs import generate_episodes
from fkn_bench.exporters import DatasetError, DatasetSource, read_dataset, write_dataset
from fkn_bench.scenarios import get_scenario

SHORT = get_scenario("ds1-flips", n_steps=300)  # sign flips and dropout: NaN poses stored and read back


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_dataset(SHORT, [0, 2], tmp_path_factory.mktemp("datasets"))


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return np.asarray(a).tobytes() == np.asarray(b).tobytes()


def test_the_dataset_holds_the_environments_episodes_bit_for_bit(written: Path) -> None:
    import minari

    assert written.name == "ds1-flips-full-v0" and written.parent.name == "fkn-bench"
    dataset = minari.MinariDataset(written / "data")
    assert dataset.total_episodes == 2 and dataset.spec.env_spec.kwargs == {"scenario": "ds1-flips", "n_steps": 300}
    env = dataset.recover_environment()
    assert env.unwrapped.scenario.config_hash() == SHORT.config_hash()
    episode = dataset[1]
    obs, info = env.reset(seed=2)
    assert _same(episode.observations["pose"][0], obs["pose"]) and info["episode_seed"] == 2
    assert _same(episode.infos["truth"], generate_episodes(SHORT, [2]).truth[0])
    for k in range(40):  # the stored actions, replayed, give the stored rewards and observations
        obs, reward, terminated, truncated, _ = env.step(episode.actions[k])
        assert _same(reward, episode.rewards[k]) and not terminated and not truncated
        assert _same(obs["pose"], episode.observations["pose"][k + 1]) and obs["valid"] == episode.observations["valid"][k + 1]
    assert episode.truncations[-1] and not episode.truncations[:-1].any() and not episode.terminations.any()
    assert np.isnan(episode.observations["pose"]).any()
    metadata = dataset.storage.metadata["fkn_bench"]
    assert metadata["seeds"] == [0, 2] and metadata["split"] == "full" and metadata["behaviour_estimator"] == "manual-ekf"
    assert metadata["config_hash"] == SHORT.config_hash() and "python" in str(metadata["provenance"]).lower()


def test_the_source_gives_the_episodes_of_a_direct_run(written: Path) -> None:
    direct = generate_episodes(SHORT, [2, 0], split="test")
    loaded = DatasetSource(str(written), "test").load([2, 0])
    for field in ("times", "truth", "measurements", "valid"):
        assert _same(getattr(loaded, field), getattr(direct, field)), field
    assert (loaded.seeds, loaded.start, loaded.scenario.config_hash()) == ((2, 0), direct.start, SHORT.config_hash())
    assert DatasetSource(str(written)).key() == DatasetSource(str(written / "data")).key()


def test_problems_are_named(written: Path, tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match=r"holds no episode of seed\(s\) \[1\] \(it holds \[0, 2\]\)"):
        DatasetSource(str(written)).load([0, 1])
    with pytest.raises(FileExistsError, match="exists: .* --force"):
        write_dataset(SHORT, [0], written.parents[1])
    with pytest.raises(DatasetError, match="dataset not found"):
        read_dataset(tmp_path / "nope")
    (tmp_path / "other" / "data").mkdir(parents=True)
    (tmp_path / "other" / "data" / "metadata.json").write_text('{"dataset_id": "x/y-v0"}')
    with pytest.raises(DatasetError, match="not an fkn-bench dataset"):
        read_dataset(tmp_path / "other")
    only_test = write_dataset(SHORT, [0], tmp_path, split="test")
    with pytest.raises(DatasetError, match="holds the test split only, not the val split"):
        DatasetSource(str(only_test), "val").load([0])


# ---------------------------------------------------------------------------- issue 34
def _copy(written: Path, tmp_path: Path) -> Path:
    """A copy of the module's dataset (its own path: read_dataset caches by path)."""
    import shutil

    copy = tmp_path / "datasets" / "fkn-bench" / written.name
    shutil.copytree(written, copy)
    return copy


def _edit_metadata(dataset: Path, change) -> None:  # noqa: ANN001
    import json

    path = dataset / "data" / "metadata.json"
    path.write_text(json.dumps(change(json.loads(path.read_text()))))


def test_checksums_are_recorded_and_checked_before_the_file_is_read(written: Path, tmp_path: Path) -> None:
    """Issue 34, finding 2: 50 random byte flips in the HDF5 file scored (RMSE 1e95); swapped
    seeds in the metadata would file each episode under the other seed."""
    import json

    recorded = json.loads((written / "data" / "metadata.json").read_text())["fkn_bench"]["sha256"]
    assert set(recorded) == {"main_data.hdf5", "fkn_bench"} and all(len(v) == 64 for v in recorded.values())
    flipped = _copy(written, tmp_path / "flipped")
    data = bytearray((flipped / "data" / "main_data.hdf5").read_bytes())
    rng = np.random.default_rng(34)
    for index in rng.choice(len(data), 50, replace=False):
        data[index] ^= 1 << int(rng.integers(8))
    (flipped / "data" / "main_data.hdf5").write_bytes(bytes(data))
    with pytest.raises(DatasetError, match=r"checksum mismatch: .*main_data\.hdf5 is damaged"):
        DatasetSource(str(flipped)).load([0])
    swapped = _copy(written, tmp_path / "swapped")
    _edit_metadata(swapped, lambda m: {**m, "fkn_bench": {**m["fkn_bench"], "seeds": [2, 0]}})
    with pytest.raises(DatasetError, match="checksum mismatch: the 'fkn_bench' metadata .* were changed"):
        read_dataset(swapped)


def test_a_dataset_without_checksums_is_read_with_a_warning(written: Path, tmp_path: Path) -> None:
    from fkn_bench.exporters.datasets import DatasetWarning

    old = _copy(written, tmp_path)
    _edit_metadata(old, lambda m: {**m, "fkn_bench": {k: v for k, v in m["fkn_bench"].items() if k != "sha256"}})
    with pytest.warns(DatasetWarning, match="written before fkn-bench recorded checksums.*--force"):
        assert read_dataset(old).episodes.seeds == (0, 2)


@pytest.mark.parametrize(("row", "column", "value", "problem"), [
    (0, 4, np.nan, r"rx = nan is not finite"),
    (1, 5, 1e300, r"ry = 1e\+300 m is beyond \+-1e\+06 m"),
    (0, 0, 2.0, r"the attitude quaternion has norm"),
])
def test_implausible_truths_are_named_errors(written: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                             row: int, column: int, value: float, problem: str) -> None:
    """Issue 34, finding 2: a NaN truth (``episode_0/infos/truth[250]``) gave exit 0 and a "2
    seeds" mean of the other seed; 1e300 did the same. A tamperer who also rewrites the checksums
    (or a dataset written before them) still gets a named error: file, episode, seed and step."""
    import h5py

    from fkn_bench.cli import main
    from fkn_bench.exporters.dataset_checks import record_checksums

    bad = _copy(written, tmp_path)
    with h5py.File(bad / "data" / "main_data.hdf5", "r+") as fh:
        fh[f"episode_{row}/infos/truth"][250, column] = value
    record_checksums(bad / "data")
    assert main(["run", "--dataset", str(bad), "--estimator", "manual-ekf", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    seed = (0, 2)[row]
    assert len(err.splitlines()) == 1 and str(bad) in err
    assert re.search(rf"episode_{row}/infos/truth\[250\] \(seed {seed}, step 250\) is implausible: {problem}", err), err


@pytest.mark.parametrize(("change", "problem"), [
    (lambda m: {**m, "seeds": [0, 0]}, r"'seeds' is \[0, 0\]; it must list distinct integer seeds"),
    (lambda m: {**m, "seeds": [-1, 2]}, r"'seeds' is \[-1, 2\]"),
    (lambda m: {**m, "seeds": ["a", 2]}, r"'seeds' is \['a', 2\]"),
    (lambda m: {**m, "seeds": [0, 2**70]}, r"'seeds' is \[0, 1180591620717411303424\]; .* in \[0, 2\*\*63\)"),
    (lambda m: {k: v for k, v in m.items() if k != "seeds"}, r"'seeds' is None"),
    (lambda m: {**m, "start": "x"}, r"'start' is 'x'; the full split of ds1-flips starts at step 0"),
    (lambda m: {**m, "split": 3}, r"'split' is 3, not one of"),
    (lambda m: {**m, "scenario": "ds1"}, r"'scenario' is str, not a JSON object"),
    (lambda m: {**m, "scenario": {**m["scenario"], "dt": "x"}}, r"the stored scenario is not valid \(.*'dt'"),
    (None, r"its metadata.json holds list, not a JSON object"),
])
def test_tampered_metadata_are_named_errors(written: Path, tmp_path: Path, change, problem: str) -> None:  # noqa: ANN001
    """Issue 34, finding 2: each of these ended in a traceback."""
    bad = _copy(written, tmp_path)
    _edit_metadata(bad, (lambda m: [m]) if change is None else (lambda m: {**m, "fkn_bench": change(m["fkn_bench"])}))
    with pytest.raises(DatasetError, match=problem):
        read_dataset(bad)


def test_episodes_of_the_wrong_shape_are_a_named_error(written: Path, tmp_path: Path) -> None:
    import h5py

    from fkn_bench.exporters.dataset_checks import record_checksums

    bad = _copy(written, tmp_path)
    with h5py.File(bad / "data" / "main_data.hdf5", "r+") as fh:
        pose = fh["episode_1/observations/pose"][:, :6]
        del fh["episode_1/observations/pose"]
        fh["episode_1/observations/pose"] = pose
    record_checksums(bad / "data")
    with pytest.raises(DatasetError, match=r"episode_1 \(seed 2\): observations/pose must be numbers of shape \(300, 7\) "
                                           r"\(the full split of ds1-flips\), got float64 \(300, 6\)"):
        read_dataset(bad)


@pytest.mark.parametrize("dataset_id", ["mydata", "..", "../x-v0", "ABSOLUTE/x-v0", "a/x-v0", "ns/../x-v0", "ns//x-v0",
                                        "ns/x-v", "x-v0/"])
def test_dataset_ids_are_checked_before_anything_is_made(tmp_path: Path, dataset_id: str) -> None:
    """Issue 34, finding 7: ``mydata`` was a minari traceback; ``..`` and absolute ids made
    directories outside --out before Minari refused them."""
    dataset_id = dataset_id.replace("ABSOLUTE", str(tmp_path / "absolute"))
    with pytest.raises(ValueError, match=f"dataset id {re.escape(repr(dataset_id))} is not a Minari dataset id"):
        write_dataset(SHORT, [0], tmp_path / "out", dataset_id=dataset_id)
    assert list(tmp_path.iterdir()) == []


def test_the_ids_accepted_are_minaris() -> None:
    from minari.dataset.minari_dataset import parse_dataset_id

    from fkn_bench.exporters.dataset_checks import check_dataset_id

    for dataset_id in ("data-v0", "fkn-bench/ds1-full-v0", "ab/cd/my_data-v12"):
        assert check_dataset_id(dataset_id) == dataset_id
        parse_dataset_id(dataset_id)


def test_a_second_writer_is_refused_while_the_first_holds_the_directory(written: Path) -> None:
    from fkn_bench.io import LockedError, directory_lock

    root = written.parents[1]
    with directory_lock(root), pytest.raises(LockedError, match="in use by another fkn-bench process writing the dataset "
                                                                 "fkn-bench/other-v0"):
        write_dataset(SHORT, [0], root, dataset_id="fkn-bench/other-v0")
    assert not (root / "fkn-bench" / "other-v0").exists()


def _data_bytes(dataset: Path) -> dict[str, bytes]:
    return {f.name: f.read_bytes() for f in sorted((dataset / "data").iterdir())}


def _leftovers(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*")
                  if p.name.startswith(".fkn-bench-dataset-") or p.name.endswith(".tmp"))


@pytest.mark.parametrize("kill", ["after-hdf5", "checksums", "namespace", "swap"])
def test_a_killed_write_leaves_nothing_trusted_and_the_rerun_gives_the_same_dataset(
        written: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, kill_at_write, kill: str) -> None:  # noqa: ANN001
    """Issue 34, finding 6: a ``dataset`` killed at any point leaves no dataset that ``run
    --dataset`` accepts (with ``--force``: the old one, or none) and its scratch is removed by the
    next write, which gives byte for byte the dataset of an uninterrupted write."""
    from fkn_bench.exporters import dataset_checks, datasets
    from tests.conftest import SimulatedKill

    root = tmp_path / "datasets"
    target = root / "fkn-bench" / written.name
    force = kill == "swap"
    if force:
        write_dataset(SHORT, [0], root)  # another dataset of that id, replaced by the killed write
    real_child, real_checksums, real_replace = datasets._in_child, dataset_checks.record_checksums, os.replace
    calls = []

    def killed(*_: object) -> None:
        raise SimulatedKill(kill)

    if kill == "after-hdf5":
        monkeypatch.setattr(datasets, "_in_child", lambda work: real_child(work) or killed())
    elif kill == "checksums":
        monkeypatch.setattr(datasets, "record_checksums", killed)
    elif kill == "swap":  # between moving the old dataset aside and moving the new one in
        def replace(src: str, dst: str) -> None:
            calls.extend([src] if os.path.isdir(src) else [])
            return killed() if len(calls) == 2 else real_replace(src, dst)

        monkeypatch.setattr(datasets.os, "replace", replace)
    real_rmtree = datasets.shutil.rmtree
    monkeypatch.setattr(datasets.shutil, "rmtree", lambda *_, **__: None)  # a killed process cleans nothing up
    if kill == "namespace":
        with kill_at_write(2) as replaced:  # after the metadata with checksums, at Minari's namespace file
            write_dataset(SHORT, [0, 2], root)
        assert [Path(p).name for p in replaced] == ["metadata.json"]
        assert list((root / "fkn-bench").glob(".namespace_metadata.json.*.killed.tmp"))
    else:
        with pytest.raises(SimulatedKill):
            write_dataset(SHORT, [0, 2], root, force=force)
    monkeypatch.setattr(datasets, "_in_child", real_child)
    monkeypatch.setattr(datasets, "record_checksums", real_checksums)
    monkeypatch.setattr(datasets.os, "replace", real_replace)
    monkeypatch.setattr(datasets.shutil, "rmtree", real_rmtree)
    assert _leftovers(root), "the kill left its scratch (removed by the next write)"
    with pytest.raises(DatasetError, match="dataset not found"):
        read_dataset(target)
    assert write_dataset(SHORT, [0, 2], root, force=force) == target
    assert _data_bytes(target) == _data_bytes(written) and _leftovers(root) == []


@pytest.mark.parametrize("free", [None, 1000])
def test_a_crash_while_writing_is_one_error_and_leaves_nothing(written: Path, tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch, free: int | None) -> None:
    """Issue 34, finding 4: h5py crashed the interpreter (exit 139) when the disk filled while it
    wrote, and left 2 MB of scratch. The HDF5 file is written by a child process: its crash is a
    WriteError, a DiskFullError naming the free space when the disk is (nearly) full."""
    import collections
    import shutil
    import signal

    from fkn_bench.exporters import datasets
    from fkn_bench.io import DiskFullError, WriteError

    root = tmp_path / "datasets"
    monkeypatch.setattr(datasets, "_create", lambda *_: os.kill(os.getpid(), signal.SIGSEGV))
    monkeypatch.setattr(datasets, "check_free_space", lambda *_: None)  # the disk fills after the check
    if free is not None:
        usage = collections.namedtuple("usage", "total used free")
        monkeypatch.setattr(shutil, "disk_usage", lambda _: usage(10**6, 10**6 - free, free))
    error = DiskFullError if free else WriteError
    match = (r"no space left on the device to write the dataset fkn-bench/ds1-flips-full-v0 .*\(1 kB free, about "
             r"\d+ kB needed\)" if free else r"cannot write the dataset .* in .*: the writing process died of signal 11")
    with pytest.raises(error, match=match):
        write_dataset(SHORT, [0, 2], root)
    assert [p.name for p in root.iterdir()] == [".fkn-bench.lock"]
