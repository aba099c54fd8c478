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

Writing (:func:`write_dataset`). The id must be Minari's ``name-vN`` or ``namespace/name-vN``
(:func:`~fkn_bench.exporters.dataset_checks.check_dataset_id`): anything else, ``..`` and absolute
paths included, is refused before a directory is made. An existing dataset of that id is replaced
only with ``force``. The datasets directory is locked for the whole command
(:func:`fkn_bench.io.directory_lock`): a second ``fkn-bench dataset`` into it meanwhile is
refused (:class:`~fkn_bench.io.LockedError`); under the lock, the scratch directories and
temporary files of killed writers are deleted. The free space is checked up front (the dataset's
size is estimated, :func:`estimated_bytes`; :class:`~fkn_bench.io.DiskFullError`), the dataset is
built in a scratch directory ``.fkn-bench-dataset-*`` inside the datasets directory (Minari ignores
hidden directories) and renamed into place when complete, with its checksums: a killed or failed
write leaves no dataset that ``fkn-bench run --dataset`` accepts, and writing it again gives the
same dataset. HDF5 is written by a child process, so that a file system that fills up while
h5py writes (h5py then crashes its process) ends in one :class:`~fkn_bench.io.WriteError` line
(a :class:`~fkn_bench.io.DiskFullError` naming the free space when the disk is full), not a crash.

Reading (:func:`read_dataset`, :class:`DatasetSource`). Before an episode is scored, the dataset's
checksums, metadata and episodes are checked (:mod:`fkn_bench.exporters.dataset_checks`: damaged
files, edited metadata and implausible truths are one-line :class:`DatasetError` s naming the
dataset, and for a truth the episode, seed and step); a dataset written before checksums were
recorded is read with a :class:`DatasetWarning`.
"""

from __future__ import annotations

import dataclasses
import errno
import faulthandler
import hashlib
import json
import os
import shutil
import signal
import tempfile
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from fkn_bench.envs import Episodes, generate_episodes
from fkn_bench.exporters.dataset_checks import (
    DatasetError,
    DatasetWarning,
    check_dataset_id,
    check_episodes,
    checked_metadata,
    file_sha256,
    record_checksums,
    verify_checksums,
)
from fkn_bench.inputs import SEED_LIMIT, check_seed
from fkn_bench.io import (
    DiskFullError,
    WriteError,
    check_free_space,
    directory_lock,
    remove_temporaries,
    write_bytes_atomic,
)
from fkn_bench.scenarios import SPLITS, Scenario, get_scenario, list_scenarios

__all__ = [
    "DatasetError", "DatasetSource", "DatasetWarning", "FORMAT_VERSION", "SCRATCH_PREFIX", "default_dataset_id",
    "estimated_bytes", "read_dataset", "write_dataset",
]

FORMAT_VERSION = 1
"""Version of the ``"fkn_bench"`` metadata of a dataset."""

ESTIMATION_BATCH = 4
"""Seeds estimated at a time while writing (the estimator's covariances of whole episodes)."""

SCRATCH_PREFIX = ".fkn-bench-dataset-"
"""Name prefix of the scratch directory a dataset is built in, inside the datasets directory."""

_BYTES_PER_STEP = 8 * (7 + 1 + 1 + 13 + 1 + 13 + 1 + 1) + 2
"""HDF5 bytes of one step: pose, valid, time, action, reward, truth, step and seed (8 bytes
each), termination and truncation (1 byte each)."""


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


def estimated_bytes(batch: int, n_steps: int) -> int:
    """About how many bytes a dataset of ``batch`` episodes of ``n_steps`` steps takes on disk
    (the HDF5 arrays plus 10% and 64 kB of HDF5 and Minari overhead; measured: 10.4 MB for two
    16000-step episodes, estimated 10.8 MB)."""
    return int(1.1 * _BYTES_PER_STEP * batch * n_steps) + 64_000


def _checked_seeds(seeds: Sequence[int]) -> Sequence[int]:
    """``seeds``, each checked by :func:`fkn_bench.inputs.check_seed`, distinct and at least one."""
    if isinstance(seeds, range) and seeds.step > 0 and 0 <= seeds.start and len(seeds) and seeds[-1] < SEED_LIMIT:
        return seeds  # (--seeds N: checked without listing N seeds)
    checked = [check_seed(seed, "seeds") for seed in seeds]
    if not checked or len(set(checked)) != len(checked):
        shown = repr(checked) if len(repr(checked)) <= 60 else repr(checked)[:57] + "..."
        raise ValueError(f"seeds must be distinct, at least one (got {shown})")
    return checked


def _exists(target: Path) -> FileExistsError:
    return FileExistsError(f"{target} exists: choose another --out or --dataset-id, or pass --force to replace it")


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

    The module docstring says how it is written: the id is checked before anything is made, the
    directory is locked (:class:`~fkn_bench.io.LockedError`), an existing dataset is replaced only
    with ``force`` (else ``FileExistsError``), the free space is checked up front and a failed
    write is a :class:`~fkn_bench.io.WriteError` (:class:`~fkn_bench.io.DiskFullError`); nothing
    partial is left in place.
    """
    scenario = get_scenario(scenario)
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; valid splits: {', '.join(SPLITS)}")
    seeds = _checked_seeds(seeds)
    dataset_id = check_dataset_id(dataset_id or default_dataset_id(scenario, split))
    root = Path(out)
    target = root / dataset_id
    if not target.resolve().is_relative_to(root.resolve()):  # (the id's rule already forbids it)
        raise ValueError(f"dataset id {dataset_id!r} would write outside {root}")
    if target.exists() and not force:  # before any work; again under the lock
        raise _exists(target)
    what = f"the dataset {dataset_id}"
    first, stop = scenario.split_bounds()[split]
    needed = estimated_bytes(len(seeds), stop - first)
    with directory_lock(root, what):
        _remove_leftovers(root, target)
        if target.exists() and not force:
            raise _exists(target)
        check_free_space(root, needed, what)
        episodes = generate_episodes(scenario, seeds, split=split)
        actions = _actions(estimator, episodes)
        _build_and_place(root, dataset_id, episodes, split, actions, estimator, needed)
    return target


def _metadata(episodes: Episodes, split: str, estimator: str, weights: dict[str, float]) -> dict[str, Any]:
    """The ``"fkn_bench"`` metadata of a dataset of ``episodes`` (module docstring; the writer
    adds the checksums)."""
    from fkn_bench.io import to_jsonable
    from fkn_bench.provenance import environment

    scenario = episodes.scenario
    return to_jsonable({
        "format": FORMAT_VERSION,
        "scenario": scenario.to_dict(),
        "config_hash": scenario.config_hash(),
        "split": split,
        "start": episodes.start,
        "seeds": list(episodes.seeds),
        "behaviour_estimator": estimator,
        "reward_weights": weights,
        "provenance": environment(),
    })


def _build_and_place(root: Path, dataset_id: str, episodes: Episodes, split: str, actions: np.ndarray, estimator: str,
                     needed: int) -> None:
    """Build the dataset in a scratch directory in ``root`` (Minari, in a child process), record
    its checksums and move it to ``root/dataset_id``; the scratch goes in every case. A failure
    is a :class:`~fkn_bench.io.WriteError` (:class:`~fkn_bench.io.DiskFullError`)."""
    from fkn_bench.envs.rewards import DEFAULT_WEIGHTS

    what = f"the dataset {dataset_id}"
    weights = dict(DEFAULT_WEIGHTS)
    ours = _metadata(episodes, split, estimator, weights)
    seeds, scenario = episodes.seeds, episodes.scenario
    description = (f"AstrobeeTumble-v0 episodes of scenario {scenario.name} ({split} split), seeds "
                   f"{seeds[0]}..{seeds[-1]} ({len(seeds)}); actions: {estimator}'s estimates; the true state in "
                   "infos['truth']")
    try:
        scratch = Path(tempfile.mkdtemp(prefix=SCRATCH_PREFIX, dir=root))
    except OSError as exc:
        raise _failure(root, needed, what, _describe(exc), _disk_full(root, _describe(exc))) from None
    failure = None
    try:
        failure = _in_child(lambda: _create(scratch, dataset_id, _buffers(episodes, actions, weights), scenario,
                                            estimator, description, ours))
        if failure is None:
            try:
                record_checksums(scratch / dataset_id / "data")
                _place(scratch, root, dataset_id)
            except WriteError:
                raise
            except OSError as exc:
                failure = _describe(exc)
        full = failure is not None and _disk_full(root, failure)  # before the scratch is deleted
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    if failure is not None:
        raise _failure(root, needed, what, failure, full)


def _remove_leftovers(root: Path, target: Path) -> None:
    """Delete what killed writers left (call under the lock): scratch directories and temporary
    files in ``root`` and in the namespace directories on the way to ``target``."""
    for leftover in root.glob(SCRATCH_PREFIX + "*"):
        if leftover.is_dir():
            shutil.rmtree(leftover, ignore_errors=True)
    for directory in (root, *(p for p in target.parents if p != root and p.is_relative_to(root))):
        remove_temporaries(directory, recursive=False)


def _create(scratch: Path, dataset_id: str, buffers: list[Any], scenario: Scenario, estimator: str, description: str,
            ours: dict[str, Any]) -> None:
    """Minari writes the dataset into ``scratch`` (run in the child process of :func:`_in_child`)."""
    import gymnasium as gym
    import minari

    os.environ["MINARI_DATASETS_PATH"] = str(scratch.resolve())  # the child's own environment; Minari wants it absolute
    env_spec = dataclasses.replace(gym.spec("AstrobeeTumble-v0"), kwargs=_environment_kwargs(scenario))
    with warnings.catch_warnings():  # Minari's advice on optional fields (author e-mail, ...)
        warnings.simplefilter("ignore", UserWarning)
        dataset = minari.create_dataset_from_buffers(
            dataset_id, buffers, env=env_spec, eval_env=env_spec, algorithm_name=estimator, author="fkn-bench",
            code_permalink="https://pypi.org/project/fkn-bench/", description=description,
        )
        dataset.storage.update_metadata({"fkn_bench": ours})


def _in_child(work: Callable[[], None]) -> str | None:
    """Run ``work`` in a forked child process and wait for it; None when it succeeded, else what
    went wrong (its exception, or its death: h5py crashes its process when the disk fills while it
    writes). The child's output is discarded; its error comes back through a pipe."""
    read_end, write_end = os.pipe()
    with warnings.catch_warnings():  # Python >= 3.12 warns of fork() beside threads: the child only writes files
        warnings.simplefilter("ignore", DeprecationWarning)
        pid = os.fork()
    if pid == 0:  # pragma: no cover - the child (coverage does not follow os.fork)
        code = 0
        try:
            os.close(read_end)
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, 1)
            os.dup2(null, 2)  # h5py prints its errors there: one line comes back instead
            faulthandler.disable()  # a crash is reported by the parent
            signal.signal(signal.SIGINT, signal.SIG_DFL)
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
            work()
        except BaseException as exc:  # noqa: BLE001 - everything goes back to the parent
            code = 1
            os.write(write_end, _describe(exc).encode("utf-8", "replace"))
        finally:
            os._exit(code)
    os.close(write_end)
    try:
        with os.fdopen(read_end, "rb") as pipe:
            message = pipe.read().decode("utf-8", "replace")
        _, status = os.waitpid(pid, 0)
    except BaseException:  # Ctrl-C or SIGTERM while waiting: end the child before the scratch goes
        try:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        except (ProcessLookupError, ChildProcessError):
            pass
        raise
    if os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0:
        return None
    if os.WIFSIGNALED(status):
        return f"the writing process died of signal {os.WTERMSIG(status)}" + (f" after {message}" if message else "")
    return message or "the writing process failed"


def _describe(exc: BaseException) -> str:
    """One line: the exception's type, errno and message (at most 500 characters)."""
    code = exc.errno if isinstance(exc, OSError) else None
    errno_text = f"[Errno {code}] " if code and f"[Errno {code}]" not in str(exc) else ""
    return f"{type(exc).__name__}: {errno_text}{' '.join(str(exc).split())}"[:500]


def _disk_full(root: Path, message: str) -> bool:
    """Whether a write into ``root`` that failed with ``message`` failed for a full disk: ENOSPC
    (or EDQUOT), or (a crash) almost nothing left free."""
    if any(f"[Errno {code}]" in message for code in (errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC))):
        return True
    try:
        return shutil.disk_usage(root).free < 64 * 1024
    except OSError:
        return False


def _failure(root: Path, needed: int, what: str, message: str, full: bool) -> WriteError:
    """The error of a failed write of ``what`` into ``root``: :class:`~fkn_bench.io.DiskFullError`
    (naming the free space now) when ``full``, else :class:`~fkn_bench.io.WriteError`."""
    if full:
        return DiskFullError(root, needed, what=what)
    return WriteError(f"cannot write {what} in {root}: {message}", root)


def _place(scratch: Path, root: Path, dataset_id: str) -> None:
    """Move the dataset built in ``scratch`` to ``root/dataset_id``: first Minari's namespace
    files (where missing), then the dataset, replacing an existing one by two renames (the old
    one goes into ``scratch``, which the caller removes)."""
    for namespace_file in sorted(scratch.rglob("namespace_metadata.json")):
        placed = root / namespace_file.relative_to(scratch)
        if not placed.exists():
            write_bytes_atomic(placed, namespace_file.read_bytes())
    built, target = scratch / dataset_id, root / dataset_id
    target.parent.mkdir(parents=True, exist_ok=True)
    if target.exists():
        os.replace(target, scratch / ".replaced")
    os.replace(built, target)


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
        raise DatasetError(f"{data / 'metadata.json'} cannot be read: {' '.join(str(exc).split())[:200]}") from None
    ours, scenario, split, start, seeds = checked_metadata(Path(path), metadata, FORMAT_VERSION)
    if not verify_checksums(Path(path), data, ours):  # before h5py opens a file that may be damaged
        warnings.warn(f"{path} was written before fkn-bench recorded checksums in datasets: its files cannot be "
                      "checked for damage (write it again with fkn-bench dataset --force to add them)",
                      DatasetWarning, stacklevel=3)
    try:
        stored = list(MinariDataset(data).iterate_episodes())
    except Exception as exc:  # noqa: BLE001 - h5py/minari errors of a damaged file
        raise DatasetError(f"{path}: the episodes cannot be read ({' '.join(str(exc).split())[:200]})") from None
    check_episodes(Path(path), stored, scenario, split, start, seeds)
    episodes = Episodes(
        scenario=scenario, seeds=seeds, start=start, times=np.array(stored[0].observations["time"], dtype=np.float64),
        truth=np.stack([e.infos["truth"] for e in stored]).astype(np.float64),
        measurements=np.stack([e.observations["pose"] for e in stored]).astype(np.float64),
        valid=np.stack([e.observations["valid"] for e in stored]).astype(bool),
    )
    for array in (episodes.times, episodes.truth, episodes.measurements, episodes.valid):
        array.flags.writeable = False  # shared between the cells of a process
    return StoredDataset(Path(path), str(metadata.get("dataset_id", "")), episodes, split, ours)


def read_dataset(path: str | Path) -> StoredDataset:
    """The dataset at ``path`` (its directory, or that directory's ``data/``), checked
    (:mod:`fkn_bench.exporters.dataset_checks`: :class:`DatasetError` naming the path and the
    problem; :class:`DatasetWarning` for a dataset without checksums), cached per process."""
    return _read(str(path))


def _digest(files: Sequence[Path]) -> str:
    """SHA-256 (16 hex digits) over the files' SHA-256 digests (each cached by path, time and
    size, :func:`~fkn_bench.exporters.dataset_checks.file_sha256`: the files of a 100 MB dataset
    are not hashed again for every cell of a grid)."""
    digest = hashlib.sha256()
    for file in files:
        digest.update(bytes.fromhex(file_sha256(file)))
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
        files = [f for f in sorted(_data_directory(Path(self.path)).rglob("*")) if f.is_file()]
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
