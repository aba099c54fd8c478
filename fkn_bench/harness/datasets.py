"""Minari datasets of scenario episodes: :func:`write_dataset` (``fkn-bench dataset``) and
:class:`DatasetSource` (``fkn-bench run --dataset``).

`Minari <https://minari.farama.org>`_ is Farama's format for datasets recorded from Gymnasium
environments. A dataset written here holds, per seed, one Minari episode exactly as
``AstrobeeTumble-v0`` reset with that seed produces it (``split="full"``; or one split of it):

* ``observations``: the environment's dict, ``pose (T, 7)`` (``wxyz`` quaternion and position, m;
  NaN where no measurement), ``valid (T,)`` (1 where ``pose`` holds one), ``time (T,)`` (s);
* ``actions (T-1, 13)``: the estimates of a behaviour estimator (``--estimator``, default the
  paper's manually tuned EKF), the action the environment scored at each step;
* ``rewards (T-1,)``: the environment's reward of those actions; ``truncations``: True at the
  last step (Gymnasium's truncation at the episode's end); ``terminations``: all False;
* ``infos``: ``truth (T, 13)`` (the hidden state, never an observation), ``step``, ``episode_seed``;
* episode metadata ``seed``: the episode seed (``reset(seed=...)``).

The dataset metadata name the environment (``env_spec``: ``AstrobeeTumble-v0`` with the scenario,
so that ``dataset.recover_environment()`` makes it) and, under ``"fkn_bench"``, the scenario's
configuration and hash, the split and its first step, the seeds, the behaviour estimator, the
reward weights and the provenance (versions, machine, commit). Arrays are float64 and stored
losslessly (HDF5), so that :class:`DatasetSource` gives back bit for bit the episodes
:func:`~fkn_bench.envs.generate_episodes` makes, and an estimator scores the same on the dataset
as on the scenario.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import tempfile
import threading
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from fkn_bench.envs import Episodes, generate_episodes
from fkn_bench.scenarios import SPLITS, Scenario, get_scenario, list_scenarios

__all__ = ["DatasetError", "DatasetSource", "FORMAT_VERSION", "default_dataset_id", "read_dataset", "write_dataset"]

FORMAT_VERSION = 1
"""Version of the ``"fkn_bench"`` metadata of a dataset."""

ESTIMATION_BATCH = 4
"""Seeds estimated at a time while writing (the estimator's covariances of whole episodes)."""

_ENVIRONMENT_LOCK = threading.Lock()  # MINARI_DATASETS_PATH is process-wide


class DatasetError(ValueError):
    """A dataset that cannot be read as an fkn-bench dataset (the message names the path)."""


def default_dataset_id(scenario: Scenario, split: str) -> str:
    """``fkn-bench/<scenario>-<split>-v0`` (Minari's ``namespace/name-vN`` form)."""
    return f"fkn-bench/{scenario.name}-{split}-v0"


def _environment_kwargs(scenario: Scenario) -> dict[str, Any]:
    """``gym.make`` keyword arguments that rebuild ``scenario``: its registered name, plus the
    fields that differ from the registered scenario of that name (or from ds1)."""
    registered = {s.name: s for s in list_scenarios()}
    base = registered.get(scenario.name, registered["ds1"])
    mine, theirs = scenario.to_dict(), base.to_dict()
    overrides = {k: v for k, v in mine.items() if k not in ("name", "description", "tags") and theirs.get(k) != v}
    return {"scenario": base.name, **overrides}


def _buffers(episodes: Episodes, actions: np.ndarray, reward_weights: dict[str, float]) -> list[Any]:
    from minari.data_collector import EpisodeBuffer

    from fkn_bench.envs.rewards import estimate_cost

    n = episodes.n_steps
    out = []
    for row, seed in enumerate(episodes.seeds):
        taken = actions[row, : n - 1]
        truncations = np.zeros(n - 1, dtype=bool)
        truncations[-1] = True
        out.append(EpisodeBuffer(
            id=None, seed=int(seed),
            observations={"pose": episodes.measurements[row], "valid": episodes.valid[row].astype(np.int64),
                          "time": np.array(episodes.times)},
            actions=taken,
            rewards=-estimate_cost(episodes.truth[row, : n - 1], taken, reward_weights),
            terminations=np.zeros(n - 1, dtype=bool),
            truncations=truncations,
            infos={"truth": episodes.truth[row], "step": np.arange(episodes.start, episodes.start + n),
                   "episode_seed": np.full(n, int(seed))},
        ))
    return out


def _actions(estimator_name: str, episodes: Episodes) -> np.ndarray:
    """The behaviour estimator's estimates ``(B, T, 13)``, :data:`ESTIMATION_BATCH` seeds at a
    time; a step without a usable estimate (before initialisation) gets the identity attitude."""
    from fkn_bench.estimators import make_estimator

    estimator = make_estimator(estimator_name, scenario=episodes.scenario)
    means = np.empty(episodes.truth.shape)
    for start in range(0, episodes.batch_size, ESTIMATION_BATCH):
        rows = slice(start, start + ESTIMATION_BATCH)
        estimates = estimator.estimate(np.array(episodes.measurements[rows]), np.array(episodes.valid[rows]),
                                       float(episodes.scenario.dt))
        means[rows] = estimates.means
    unusable = ~np.isfinite(means).all(axis=-1) | (np.sum(means[..., :4] ** 2, axis=-1) < 1e-12)
    means[unusable] = np.r_[1.0, np.zeros(12)]
    return means


def write_dataset(
    scenario: str | Scenario,
    seeds: Sequence[int],
    out: str | Path,
    *,
    split: str = "full",
    estimator: str = "manual-ekf",
    dataset_id: str | None = None,
    force: bool = False,
) -> Path:
    """Write the episodes of ``seeds`` (their ``split``) as a Minari dataset under the datasets
    directory ``out`` (the dataset is ``out/<dataset_id>``, default :func:`default_dataset_id`)
    and return its directory. Read it with ``fkn-bench run --dataset DIR``,
    :class:`DatasetSource` or ``MINARI_DATASETS_PATH=out`` and ``minari.load_dataset(id)``.

    The dataset is built beside its place and moved there when complete, so that an interrupted
    write leaves no partial dataset; an existing one is replaced only with ``force``.
    """
    import gymnasium as gym
    import minari

    from fkn_bench.envs.rewards import DEFAULT_WEIGHTS
    from fkn_bench.io import to_jsonable
    from fkn_bench.provenance import environment

    scenario = get_scenario(scenario)
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; valid splits: {', '.join(SPLITS)}")
    seeds = [int(s) for s in seeds]
    if not seeds or min(seeds) < 0 or len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds must be distinct non-negative integers (got {seeds})")
    dataset_id = dataset_id or default_dataset_id(scenario, split)
    root = Path(out)
    target = root / dataset_id
    if target.exists() and not force:
        raise FileExistsError(f"{target} exists: choose another --out or --dataset-id, or pass --force to replace it")
    episodes = generate_episodes(scenario, seeds, split=split)
    actions = _actions(estimator, episodes)
    spec = gym.spec("AstrobeeTumble-v0")
    env_spec = dataclasses.replace(spec, kwargs=_environment_kwargs(scenario))
    weights = dict(DEFAULT_WEIGHTS)
    root.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=".fkn-bench-dataset-", dir=root) as scratch, _ENVIRONMENT_LOCK:
        previous = os.environ.get("MINARI_DATASETS_PATH")
        os.environ["MINARI_DATASETS_PATH"] = str(Path(scratch).resolve())  # (Minari needs it absolute)
        try:
            with warnings.catch_warnings():  # Minari's advice on optional fields (author e-mail, ...)
                warnings.simplefilter("ignore", UserWarning)
                dataset = minari.create_dataset_from_buffers(
                    dataset_id, _buffers(episodes, actions, weights), env=env_spec, eval_env=env_spec,
                    algorithm_name=estimator, author="fkn-bench", code_permalink="https://pypi.org/project/fkn-bench/",
                    description=(f"AstrobeeTumble-v0 episodes of scenario {scenario.name} ({split} split), seeds "
                                 f"{seeds[0]}..{seeds[-1]} ({len(seeds)}); actions: {estimator}'s estimates; the true "
                                 "state in infos['truth']"),
                )
                dataset.storage.update_metadata({"fkn_bench": to_jsonable({
                    "format": FORMAT_VERSION,
                    "scenario": scenario.to_dict(),
                    "config_hash": scenario.config_hash(),
                    "split": split,
                    "start": episodes.start,
                    "seeds": seeds,
                    "behaviour_estimator": estimator,
                    "reward_weights": weights,
                    "provenance": environment(),
                })})
        finally:
            if previous is None:
                os.environ.pop("MINARI_DATASETS_PATH", None)
            else:
                os.environ["MINARI_DATASETS_PATH"] = previous
        built = Path(scratch) / dataset_id
        target.parent.mkdir(parents=True, exist_ok=True)
        for namespace_file in Path(scratch).rglob("namespace_metadata.json"):
            placed = root / namespace_file.relative_to(scratch)
            if not placed.exists():
                placed.parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(namespace_file, placed)
        if target.exists():
            shutil.rmtree(target)
        os.replace(built, target)
    return target


@dataclass(frozen=True, eq=False)
class StoredDataset:
    """A dataset as read: its episodes (all stored seeds, in stored order) and metadata."""

    path: Path
    dataset_id: str
    episodes: Episodes
    split: str
    metadata: dict[str, Any]


def _data_directory(path: Path) -> Path:
    if not path.exists():
        raise DatasetError(f"dataset not found: {path}")
    data = path if (path / "metadata.json").is_file() else path / "data"
    if not (data / "metadata.json").is_file():
        raise DatasetError(f"{path} is not a Minari dataset (no metadata.json in it or in its data/ directory)")
    return data


@lru_cache(maxsize=2)
def _read(path: str) -> StoredDataset:
    from minari import MinariDataset

    data = _data_directory(Path(path))
    try:
        metadata = json.loads((data / "metadata.json").read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise DatasetError(f"{data / 'metadata.json'} cannot be read: {exc}") from None
    ours = metadata.get("fkn_bench")
    if not isinstance(ours, dict) or "scenario" not in ours:
        raise DatasetError(f"{path} is not an fkn-bench dataset: its metadata lack 'fkn_bench' (write one with "
                           "fkn-bench dataset)")
    if ours.get("format") != FORMAT_VERSION:
        raise DatasetError(f"{path}: fkn-bench dataset format {ours.get('format')!r}, this version reads {FORMAT_VERSION}")
    scenario = Scenario.from_dict(ours["scenario"])
    if scenario.config_hash() != ours.get("config_hash"):
        raise DatasetError(f"{path}: the scenario configuration does not match its hash (edited metadata?)")
    try:
        dataset = MinariDataset(data)
        stored = list(dataset.iterate_episodes())
    except Exception as exc:  # noqa: BLE001 - h5py/minari errors of a damaged file
        raise DatasetError(f"{path}: the episodes cannot be read ({' '.join(str(exc).split())[:200]})") from None
    seeds = tuple(int(s) for s in ours["seeds"])
    if len(stored) != len(seeds):
        raise DatasetError(f"{path}: {len(stored)} episodes stored, the metadata list {len(seeds)} seeds")
    n = len(stored[0].observations["time"]) if stored else 0
    if any(len(e.observations["time"]) != n or e.infos["truth"].shape != (n, 13) for e in stored):
        raise DatasetError(f"{path}: episodes of different lengths or without infos['truth'] (T, 13)")
    episodes = Episodes(
        scenario=scenario, seeds=seeds, start=int(ours["start"]), times=np.array(stored[0].observations["time"]),
        truth=np.stack([e.infos["truth"] for e in stored]).astype(np.float64),
        measurements=np.stack([e.observations["pose"] for e in stored]).astype(np.float64),
        valid=np.stack([e.observations["valid"] for e in stored]).astype(bool),
    )
    for array in (episodes.times, episodes.truth, episodes.measurements, episodes.valid):
        array.flags.writeable = False  # shared between the cells of a process
    return StoredDataset(Path(path), str(metadata.get("dataset_id", "")), episodes, str(ours["split"]), ours)


def read_dataset(path: str | Path) -> StoredDataset:
    """The dataset at ``path`` (its directory, or that directory's ``data/``), checked
    (:class:`DatasetError` naming the path and the problem), cached per process."""
    return _read(str(path))


@lru_cache(maxsize=8)
def _digest(files: tuple[tuple[str, int, int], ...]) -> str:
    """SHA-256 (16 hex digits) of the files' contents; cached by their paths, times and sizes, so
    that the key of a 100 MB dataset is not hashed again for every cell of a grid."""
    digest = hashlib.sha256()
    for name, _, _ in files:
        with open(name, "rb") as fh:
            digest.update(hashlib.file_digest(fh, "sha256").digest())
    return digest.hexdigest()[:16]


@dataclass(frozen=True)
class DatasetSource:
    """Episodes read from an fkn-bench Minari dataset (:func:`write_dataset`), for the harness.

    A dataset of whole episodes (``split="full"``) gives any split, cut as
    :func:`~fkn_bench.envs.generate_episodes` cuts it; a dataset of one split gives that split.
    The results are filed under the scenario's name, so that they line up with a direct run;
    the ``key`` hashes the dataset's files, so resume notices another dataset.
    """

    path: str
    split: str = "test"

    def stored(self) -> StoredDataset:
        return read_dataset(self.path)

    @property
    def label(self) -> str:
        return self.scenario.name

    @property
    def scenario(self) -> Scenario:
        return self.stored().episodes.scenario

    @property
    def seeds(self) -> tuple[int, ...]:
        return self.stored().episodes.seeds

    def key(self) -> str:
        files = tuple((str(f), f.stat().st_mtime_ns, f.stat().st_size)
                      for f in sorted(_data_directory(Path(self.path)).rglob("*")) if f.is_file())
        return f"dataset:{_digest(files)}:{self.split}"

    def describe(self) -> dict[str, Any]:
        stored = self.stored()
        return {
            "kind": "dataset",
            "path": self.path,
            "dataset_id": stored.dataset_id,
            "stored_split": stored.split,
            "split": self.split,
            "scenario": self.scenario.name,
            "config_hash": self.scenario.config_hash(),
            "behaviour_estimator": stored.metadata.get("behaviour_estimator"),
        }

    def _window(self) -> Episodes:
        stored = self.stored()
        if stored.split == self.split:
            return stored.episodes
        if stored.split != "full":
            raise DatasetError(f"{self.path} holds the {stored.split} split only, not the {self.split} split")
        return stored.episodes.split(self.split)

    def load(self, seeds: Sequence[int]) -> Episodes:
        episodes = self._window()
        rows = {seed: row for row, seed in enumerate(episodes.seeds)}
        missing = [int(s) for s in seeds if int(s) not in rows]
        if missing:
            raise DatasetError(f"{self.path} holds no episode of seed(s) {missing} (it holds {list(episodes.seeds)})")
        index = [rows[int(s)] for s in seeds]
        return Episodes(episodes.scenario, tuple(int(s) for s in seeds), episodes.start, episodes.times,
                        episodes.truth[index], episodes.measurements[index], episodes.valid[index])
