"""Minari datasets (issue 18): what ``write_dataset`` stores is the environment's episodes bit for
bit, Minari reads it, and ``DatasetSource`` gives the harness the episodes a direct run uses."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import fkn_bench  # noqa: F401  (registers the environment)
from fkn_bench.envs import generate_episodes
from fkn_bench.harness import DatasetError, DatasetSource, read_dataset, write_dataset
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
