"""What an fkn-bench dataset (:mod:`fkn_bench.exporters.datasets`) must be before it is scored: its
id, its checksums, its metadata and its episodes. Every problem is a one-line
:class:`DatasetError` naming the dataset and what is wrong.

* **Ids** (:func:`check_dataset_id`): Minari's ``name-vN`` or ``namespace/name-vN``
  (``namespace`` of at least two characters, possibly nested ``a/b``; letters, digits, ``-``,
  ``_``): ``mydata`` (no version), ``..`` and absolute paths are refused before anything is
  written, so that a dataset never lands outside its datasets directory.
* **Checksums** (:func:`record_checksums`, :func:`verify_checksums`): the writer records, under
  the ``"fkn_bench"`` metadata's ``"sha256"``, the SHA-256 of every data file beside
  ``metadata.json`` (``main_data.hdf5``) and of the ``"fkn_bench"`` metadata itself (canonical
  JSON: sorted keys, no spaces, without ``"sha256"``). The reader checks them before the HDF5
  file is opened: a changed byte is a "checksum mismatch" error, never a score. A dataset written
  before checksums were recorded (no ``"sha256"``) is read with a :class:`DatasetWarning` saying
  that it cannot be checked (rewrite it with ``fkn-bench dataset --force``).
* **Metadata** (:func:`checked_metadata`): format, scenario and its hash, split, ``start`` (the
  split's first step) and ``seeds`` (distinct integers in ``[0, 2**63)``, one per episode) have
  the types and values the writer gives them.
* **Episodes** (:func:`check_episodes`): the shapes the writer gives them (``pose (T, 7)``,
  ``valid``/``time (T,)``, ``infos["truth"] (T, 13)``, ``T`` the split's length), each episode's
  ``infos["episode_seed"]`` its seed in the metadata, times finite and shared, validity flags 0 or
  1 with a finite pose where 1, and plausible truths (:mod:`fkn_bench.recordings.plausibility`:
  finite, ``|position| <= 1e6 m``, rates ``<= 1e3``, unit quaternions), else an error naming
  ``episode_<i>/infos/truth[<row>]``, its seed and step.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Mapping, Sequence
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from fkn_bench.inputs import check_seed
from fkn_bench.recordings.plausibility import first_implausible
from fkn_bench.scenarios import SPLITS, Scenario

__all__ = [
    "DatasetError", "DatasetWarning", "DATASET_ID_PATTERN", "check_dataset_id", "checked_metadata",
    "check_episodes", "file_sha256", "is_seed", "record_checksums", "verify_checksums",
]

DATASET_ID_PATTERN = re.compile(r"(?:(?P<namespace>[-\w]+(?:/[-\w]+)*)/)?(?P<name>[-\w]+?)-v(?P<version>\d+)")
"""Dataset ids fkn-bench writes: Minari's ``(namespace/)name-vN`` with a version and no empty,
``.`` or ``..`` component (Minari also wants a namespace of two characters or more)."""

METADATA_KEY = "fkn_bench"
CHECKSUM_KEY = "sha256"


class DatasetError(ValueError):
    """A dataset that cannot be read as an fkn-bench dataset (the message names the path)."""


class DatasetWarning(UserWarning):
    """A dataset read without a check (one written before checksums were recorded)."""


def check_dataset_id(dataset_id: Any) -> str:
    """``dataset_id`` when it is a valid id (module docstring), else ``ValueError`` naming the rule."""
    if isinstance(dataset_id, str):
        match = DATASET_ID_PATTERN.fullmatch(dataset_id)
        namespace = match and match.group("namespace")
        if match and (namespace is None or len(namespace) >= 2):
            return dataset_id
    raise ValueError(
        f"dataset id {dataset_id!r} is not a Minari dataset id: it must be NAME-vN or NAMESPACE/NAME-vN (letters, "
        "digits, '-' and '_'; a namespace of two characters or more, nested with '/'), e.g. fkn-bench/ds1-full-v0"
    )


# ---------------------------------------------------------------------------- checksums
@lru_cache(maxsize=32)
def _sha256(name: str, mtime_ns: int, size: int) -> str:
    with open(name, "rb") as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()


def file_sha256(path: Path) -> str:
    """The SHA-256 (hex) of the file's bytes; cached by path, modification time and size, so that
    a dataset checked on read is not hashed again for its ``DatasetSource.key()``."""
    stat = path.stat()
    return _sha256(str(path), stat.st_mtime_ns, stat.st_size)


def _metadata_digest(ours: Mapping[str, Any]) -> str:
    document = {k: v for k, v in ours.items() if k != CHECKSUM_KEY}
    return hashlib.sha256(json.dumps(document, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def _data_files(data: Path) -> list[Path]:
    return sorted(f for f in data.iterdir() if f.is_file() and f.name != "metadata.json" and not f.name.startswith("."))


def record_checksums(data: Path) -> dict[str, Any]:
    """Add the checksums (module docstring) to the ``"fkn_bench"`` metadata in ``data/metadata.json``
    (a dataset's ``data`` directory, complete); returns the whole metadata as written."""
    from fkn_bench.io import write_text_atomic

    metadata = json.loads((data / "metadata.json").read_text(encoding="utf-8"))
    ours = metadata[METADATA_KEY]
    ours[CHECKSUM_KEY] = {**{f.name: file_sha256(f) for f in _data_files(data)}, METADATA_KEY: _metadata_digest(ours)}
    write_text_atomic(data / "metadata.json", json.dumps(metadata))
    return metadata


def verify_checksums(path: Path, data: Path, ours: Mapping[str, Any]) -> bool:
    """Check the recorded checksums of the dataset at ``path`` (its ``data`` directory holds the
    files) against the files and the metadata: :class:`DatasetError` on a mismatch or a missing
    file; False when none are recorded (a dataset written before they were)."""
    recorded = ours.get(CHECKSUM_KEY)
    if recorded is None:
        return False
    if not (isinstance(recorded, dict) and METADATA_KEY in recorded and all(isinstance(v, str) for v in recorded.values())):
        raise DatasetError(f"{path}: the recorded checksums (metadata 'fkn_bench' 'sha256') are damaged")
    if recorded[METADATA_KEY] != _metadata_digest(ours):
        raise DatasetError(f"{path}: checksum mismatch: the 'fkn_bench' metadata in {data / 'metadata.json'} were changed "
                           "after the dataset was written (write it again with fkn-bench dataset --force)")
    for name, digest in recorded.items():
        if name == METADATA_KEY:
            continue
        file = data / name
        if Path(name).name != name or not file.is_file():
            raise DatasetError(f"{path}: the data file {name} is missing (write the dataset again with fkn-bench dataset)")
        if file_sha256(file) != digest:
            raise DatasetError(f"{path}: checksum mismatch: {file} is damaged or was changed after the dataset was "
                               "written (SHA-256 differs; write it again with fkn-bench dataset --force)")
    return True


# ---------------------------------------------------------------------------- metadata
def _integer(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def is_seed(value: Any) -> bool:
    """Whether ``value`` is an episode seed (:func:`fkn_bench.inputs.check_seed`: an integer, not
    a bool, in ``[0, 2**63)``: seeds are stored as int64)."""
    try:
        check_seed(value)
    except ValueError:
        return False
    return True


def checked_metadata(
    path: Path, metadata: Any, format_version: int
) -> tuple[dict[str, Any], Scenario, str, int, tuple[int, ...]]:
    """The ``"fkn_bench"`` metadata of the dataset at ``path`` (from ``metadata.json``) checked
    (module docstring): ``(metadata, scenario, split, start, seeds)``."""
    if not isinstance(metadata, dict):
        raise DatasetError(f"{path}: its metadata.json holds {type(metadata).__name__}, not a JSON object")
    ours = metadata.get(METADATA_KEY)
    if not isinstance(ours, dict) or "scenario" not in ours:
        raise DatasetError(f"{path} is not an fkn-bench dataset: its metadata lack 'fkn_bench' (write one with "
                           "fkn-bench dataset)")
    if ours.get("format") != format_version:
        raise DatasetError(f"{path}: fkn-bench dataset format {ours.get('format')!r}, this version reads {format_version}")
    if not isinstance(ours["scenario"], dict):
        raise DatasetError(f"{path}: metadata 'scenario' is {type(ours['scenario']).__name__}, not a JSON object")
    try:
        scenario = Scenario.from_dict(ours["scenario"])
    except (ValueError, TypeError, AttributeError) as exc:  # ConfigError is a ValueError
        raise DatasetError(f"{path}: the stored scenario is not valid ({' '.join(str(exc).split())[:200]})") from None
    if scenario.config_hash() != ours.get("config_hash"):
        raise DatasetError(f"{path}: the scenario configuration does not match its hash (edited metadata?)")
    split = ours.get("split")
    if split not in SPLITS:
        raise DatasetError(f"{path}: metadata 'split' is {split!r}, not one of {', '.join(SPLITS)}")
    start, expected = ours.get("start"), scenario.split_bounds()[split][0]
    if not _integer(start) or start != expected:
        raise DatasetError(f"{path}: metadata 'start' is {start!r}; the {split} split of {scenario.name} starts at "
                           f"step {expected}")
    seeds = ours.get("seeds")
    if (not isinstance(seeds, list) or not seeds or not all(map(is_seed, seeds))
            or len(set(seeds)) != len(seeds)):
        shown = repr(seeds) if len(repr(seeds)) <= 60 else repr(seeds)[:57] + "..."
        raise DatasetError(f"{path}: metadata 'seeds' is {shown}; it must list distinct integer seeds in [0, 2**63), "
                           "one per episode")
    return ours, scenario, split, start, tuple(seeds)


# ---------------------------------------------------------------------------- episodes
def check_episodes(path: Path, episodes: Sequence[Any], scenario: Scenario, split: str, start: int,
                   seeds: tuple[int, ...]) -> None:
    """Check Minari's episodes of the dataset at ``path`` against its metadata (module docstring)."""
    if len(episodes) != len(seeds):
        raise DatasetError(f"{path}: {len(episodes)} episodes stored, the metadata list {len(seeds)} seeds")
    first, stop = scenario.split_bounds()[split]
    n = stop - first
    shapes = {"observations/pose": (n, 7), "observations/valid": (n,), "observations/time": (n,), "infos/truth": (n, 13),
              "infos/episode_seed": (n,)}
    times = None
    for row, (episode, seed) in enumerate(zip(episodes, seeds)):
        where = f"episode_{row} (seed {seed})"
        arrays = {}
        for name, shape in shapes.items():
            group, key = name.split("/")
            container = getattr(episode, group, None)
            array = np.asarray(container[key]) if isinstance(container, dict) and key in container else None
            if array is None or array.shape != shape or array.dtype.kind not in "iuf":
                got = "none" if array is None else f"{array.dtype} {array.shape}"
                raise DatasetError(f"{path}: {where}: {name} must be numbers of shape {shape} (the {split} split of "
                                   f"{scenario.name}), got {got}")
            arrays[name] = array
        if not np.all(arrays["infos/episode_seed"] == seed):
            raise DatasetError(f"{path}: {where}: infos/episode_seed is not {seed} (the metadata's seeds and the "
                               "episodes disagree)")
        valid, pose = arrays["observations/valid"], arrays["observations/pose"]
        if not np.isin(valid, (0, 1)).all() or not np.isfinite(pose[valid == 1]).all():
            raise DatasetError(f"{path}: {where}: observations/valid must be 0 or 1, with a finite pose where it is 1")
        if times is None:
            times = arrays["observations/time"]
            if not np.isfinite(times).all():
                raise DatasetError(f"{path}: {where}: observations/time is not finite")
        elif not np.array_equal(arrays["observations/time"], times):
            raise DatasetError(f"{path}: {where}: observations/time differs from episode_0's")
        implausible = first_implausible(arrays["infos/truth"])
        if implausible is not None:
            (k,), problem = implausible
            raise DatasetError(f"{path}: the true state episode_{row}/infos/truth[{k}] (seed {seed}, step {start + k}) is "
                               f"implausible: {problem} (fkn_bench.recordings.plausibility)")
