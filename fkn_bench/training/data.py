"""Training data for filters trained through their recursion: windows of consecutive samples.

A scenario's data set is the episode of its ``dataset_seed`` (the paper's single recording),
split 80/10/10 into train, val and test (FlexKalmanNet section 4.1). Training uses windows of
``window`` consecutive samples of the train split (the paper's batch of 512 consecutive samples),
cut every ``stride`` samples; a batch is a set of windows that run through the filter in
parallel as its batch axis. Validation runs the filter over the whole val split, as evaluation
does over the test split.

An episode-split scenario (a prior family, ``split_mode = "episodes"``) has no single recording:
its data set is at least :data:`PRIOR_EPISODES` whole episodes of its train pool (each a different
truth drawn from its prior), cut into windows, and as many episodes of its val pool for validation,
episodes ``dataset_seed, dataset_seed + 1, ...`` of each pool; its test episodes are never seen.

A data set may mix scenarios (a sequence of them, with one ``dt``): its windows are those of every
scenario, and validation runs over every scenario's val split. A mixture trains one estimator for
several kinds of motion (e.g. constant rate and free tumbling).

The measurement schedule of the training windows can differ from the scenario's
(``train_measurement_every``): training with a measurement at every step and evaluating with one
every 10 is what the paper's data allow. A different schedule is a different noise realisation
of the same ground truth (noise draws are keyed by scheduled step, see
:mod:`fkn_bench.envs.measurements`).
"""

from __future__ import annotations

import copy
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import torch
from torch import Tensor

from fkn_bench.scenarios import PRIOR_EPISODES, Scenario, get_scenario
from fkn_bench.types import Bool, Float

__all__ = ["PRIOR_EPISODES", "Sequences", "TrainingData", "episodes_of", "training_data"]


@dataclass(frozen=True, eq=False)
class Sequences:
    """A batch of sequences as torch tensors (batch first).

    Attributes:
        measurements: ``(B, T, 7)``, NaN where missing.
        mask: ``(B, T)`` bool.
        truth: ``(B, T, 13)``.
    """

    measurements: Float[Tensor, "B T 7"]
    mask: Bool[Tensor, "B T"]
    truth: Float[Tensor, "B T 13"]

    @property
    def batch_size(self) -> int:
        return self.measurements.shape[0]

    def select(self, index: Tensor) -> Sequences:
        return Sequences(self.measurements[index], self.mask[index], self.truth[index])

    def to(self, device: torch.device | str) -> Sequences:
        """The sequences on ``device`` (themselves when already there)."""
        return Sequences(self.measurements.to(device), self.mask.to(device), self.truth.to(device))


def episodes_of(scenario: Scenario, episodes: int) -> int:
    """Episodes of ``scenario`` in a data set of ``episodes`` configured: at least
    :data:`PRIOR_EPISODES` for an episode-split scenario (module docstring)."""
    return max(int(episodes), PRIOR_EPISODES) if scenario.split_mode == "episodes" else int(episodes)


def _split(scenario: Scenario, split: str, every: int, dtype: torch.dtype, episodes: int = 1) -> Sequences:
    from fkn_bench.envs import generate_episodes

    seeds = [scenario.dataset_seed + i for i in range(episodes_of(scenario, episodes))]
    episode = generate_episodes(scenario.replace(measurement_every=every), seeds, split=split)
    return Sequences(torch.as_tensor(episode.measurements, dtype=dtype), torch.as_tensor(episode.valid),
                     torch.as_tensor(episode.truth, dtype=dtype))


class TrainingData:
    """Train windows and the validation sequences of a scenario's data set (or of a mixture:
    ``scenario`` a sequence of scenarios; ``scenario`` is then the first, ``scenarios`` all).

    Args:
        window: samples per training window (paper: 512).
        stride: samples between window starts (default: ``window``, non-overlapping).
        train_measurement_every: measurement schedule of the training windows (default: the
            scenario's).
        episodes: episodes in the data set: seeds ``dataset_seed, dataset_seed + 1, ...`` (the
            paper has one recording: 1; an episode-split scenario at least
            :data:`PRIOR_EPISODES` per pool, :func:`episodes_of`). Training windows come from
            every episode's train split, validation runs over every episode's val split.
    """

    def __init__(
        self,
        scenario: str | Scenario | Sequence[str | Scenario],
        *,
        window: int = 512,
        stride: int | None = None,
        train_measurement_every: int | None = None,
        episodes: int = 1,
        dtype: torch.dtype = torch.float64,
    ) -> None:
        mixture = not isinstance(scenario, (str, Scenario))
        self.scenarios = tuple(get_scenario(s) for s in (scenario if mixture else [scenario]))  # type: ignore[union-attr]
        self.scenario = self.scenarios[0]
        if not self.scenarios or len({s.dt for s in self.scenarios}) != 1:
            raise ValueError(f"a mixture needs scenarios with one dt (got {[(s.name, s.dt) for s in self.scenarios]})")
        if window < 2:
            raise ValueError(f"window must be >= 2 samples (got {window})")
        stride = window if stride is None else stride
        if stride < 1:
            raise ValueError(f"stride must be >= 1 (got {stride})")
        self.window, self.stride = int(window), int(stride)
        self.train_measurement_every = int(train_measurement_every or self.scenario.measurement_every)
        if episodes < 1:
            raise ValueError(f"episodes must be >= 1 (got {episodes})")
        self.episodes = int(episodes)
        self.dtype = dtype
        every = train_measurement_every
        parts = [_windows(_split(s, "train", int(every or s.measurement_every), dtype, self.episodes), window, stride)
                 for s in self.scenarios]
        self.train = _concat([windows for windows, _ in parts])
        train = self.train_full = _concat([full for _, full in parts])
        self.val = _concat([_split(s, "val", s.measurement_every, dtype, self.episodes) for s in self.scenarios])
        positions = train.measurements[train.mask][:, 4:7]
        self.position_mean = positions.mean(0)
        self.position_std = positions.std(0).clamp_min(1e-9)

    @property
    def n_windows(self) -> int:
        return self.train.batch_size

    def to(self, device: torch.device | str) -> TrainingData:
        """The data set with its sequences on ``device``: itself when they are there already,
        else a copy (this one, which :func:`training_data` may share, is left as it is)."""
        device = torch.device(device)
        if self.train.measurements.device == device:
            return self
        moved = copy.copy(self)
        moved.train, moved.train_full, moved.val = (s.to(device) for s in (self.train, self.train_full, self.val))
        moved.position_mean, moved.position_std = self.position_mean.to(device), self.position_std.to(device)
        return moved

    def batches(self, windows_per_batch: int, generator: torch.Generator) -> Iterator[Sequences]:
        """Shuffled batches of training windows (the last one may be smaller); the order is
        drawn on ``generator``'s device (the CPU's: the same windows on every device)."""
        order = torch.randperm(self.n_windows, generator=generator, device=generator.device)
        for start in range(0, self.n_windows, windows_per_batch):
            yield self.train.select(order[start : start + windows_per_batch])

    def describe(self) -> dict[str, object]:
        mixture = len(self.scenarios) > 1
        return {
            "scenario": "+".join(s.name for s in self.scenarios) if mixture else self.scenario.name,
            "config_hash": [s.config_hash() for s in self.scenarios] if mixture else self.scenario.config_hash(),
            "dataset_seed": self.scenario.dataset_seed,
            "episodes": self.episodes,
            **({"episodes_per_pool": {s.name: episodes_of(s, self.episodes) for s in self.scenarios}}
               if any(s.split_mode == "episodes" for s in self.scenarios) else {}),
            "window": self.window,
            "stride": self.stride,
            "windows": self.n_windows,
            "train_measurement_every": self.train_measurement_every,
            "val_measurement_every": self.scenario.measurement_every,
            "position_mean_m": np.round(self.position_mean.cpu().numpy(), 6).tolist(),
            "position_std_m": np.round(self.position_std.cpu().numpy(), 6).tolist(),
        }


def _windows(split: Sequences, window: int, stride: int) -> tuple[Sequences, Sequences]:
    """Windows of ``window`` samples every ``stride`` of every episode, and the split itself."""
    length = split.measurements.shape[1]
    if length < window:
        raise ValueError(f"the train split has {length} samples, fewer than one window of {window}")
    starts = torch.arange(0, length - window + 1, stride)
    index = starts[:, None] + torch.arange(window)[None, :]
    flat = lambda t: t[:, index].flatten(0, 1)  # noqa: E731  (episodes x windows, window, ...)
    return Sequences(flat(split.measurements), flat(split.mask), flat(split.truth)), split


def _concat(parts: Sequence[Sequences]) -> Sequences:
    """The sequences of several parts (of one length) along the batch axis."""
    if len(parts) == 1:
        return parts[0]
    return Sequences(*(torch.cat([getattr(p, f) for p in parts]) for f in ("measurements", "mask", "truth")))


@lru_cache(maxsize=4)
def _cached(scenario: Scenario | tuple[Scenario, ...], window: int, stride: int | None, every: int | None, episodes: int) -> TrainingData:
    return TrainingData(scenario, window=window, stride=stride, train_measurement_every=every, episodes=episodes)


def training_data(scenario: Scenario | Sequence[Scenario], config: object) -> TrainingData:
    """The :class:`TrainingData` of ``scenario`` with ``config``'s data protocol (``window``,
    ``stride``, ``train_measurement_every``, ``episodes``: a
    :class:`~fkn_bench.training.TrainConfig`); the last few are kept (a sweep's trials share them)."""
    c = config
    key = scenario if isinstance(scenario, Scenario) else tuple(scenario)
    return _cached(key, int(c.window), c.stride, c.train_measurement_every, int(c.episodes))  # type: ignore[attr-defined]
