"""The benchmark grid: estimator x source (scenario) x seed chunk.

Seeds are cut into chunks of :data:`SEED_CHUNK` consecutive entries of the seed list (a fixed
function of that list, independent of the backend and worker count). Each chunk is one cell,
filtered as one batch, so the batched computation inside a cell, and hence every metric, is the
same on every backend.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from fkn_bench.harness.sources import EpisodeSource
from fkn_bench.metrics import MetricSettings

__all__ = ["SEED_CHUNK", "ONLINE_STEPS", "CellSpec", "chunk_seeds", "build_grid", "safe_name"]

SEED_CHUNK = 10
"""Seeds per cell."""

ONLINE_STEPS = 200
"""Steps of the timed online run of each cell (``reset`` + ``step``, first seed of the cell)."""

CELL_FORMAT_VERSION = 1
"""Bump when the meaning of stored cell results changes: older cells are then recomputed."""


def chunk_seeds(seeds: Sequence[int], size: int = SEED_CHUNK) -> list[tuple[int, ...]]:
    """Consecutive chunks of ``size`` seeds, in list order (the last may be shorter)."""
    if size < 1:
        raise ValueError(f"chunk size must be >= 1 (got {size})")
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("at least one seed is required")
    if len(set(seeds)) != len(seeds):
        raise ValueError("seeds must be distinct")
    if min(seeds) < 0:
        raise ValueError("seeds must be non-negative")
    return [tuple(seeds[i : i + size]) for i in range(0, len(seeds), size)]


def safe_name(name: str) -> str:
    """A file-system-safe version of an estimator or scenario name."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name) or "_"


@dataclass(frozen=True)
class CellSpec:
    """One unit of work: filter ``seeds`` of ``source`` with ``estimator`` and score them.

    Attributes:
        estimator: registered estimator name.
        source: where the episodes come from (:class:`~fkn_bench.harness.sources.EpisodeSource`).
        seeds: the seed chunk.
        settings: metric settings.
        estimator_fingerprint: short hash of the estimator's configuration (``to_config()``), so
            that a retuned estimator is recomputed on resume ("" when unknown).
        online_steps: length of the timed online run.
        estimator_options: keyword options for the estimator's factory, as sorted pairs.
    """

    estimator: str
    source: EpisodeSource
    seeds: tuple[int, ...]
    settings: MetricSettings
    estimator_fingerprint: str = ""
    online_steps: int = ONLINE_STEPS
    estimator_options: tuple[tuple[str, Any], ...] = ()

    @property
    def scenario(self) -> str:
        return self.source.label

    @property
    def name(self) -> str:
        """Human-readable cell name, e.g. ``manual-ekf/ds1/seeds-0-9``."""
        return f"{self.estimator}/{self.scenario}/seeds-{self.seeds[0]}-{self.seeds[-1]}"

    def key(self) -> dict[str, Any]:
        """Everything that determines the cell's deterministic results (resume compares it)."""
        return {
            "format_version": CELL_FORMAT_VERSION,
            "estimator": self.estimator,
            "estimator_fingerprint": self.estimator_fingerprint,
            **({"estimator_options": [list(item) for item in self.estimator_options]} if self.estimator_options else {}),
            "source": self.source.key(),
            "seeds": list(self.seeds),
            "settings": self.settings.to_dict(),
        }

    def key_hash(self) -> str:
        return hashlib.sha256(json.dumps(self.key(), sort_keys=True).encode()).hexdigest()[:16]


def build_grid(
    estimators: Sequence[str],
    sources: Sequence[EpisodeSource],
    seeds: Sequence[int],
    *,
    settings: MetricSettings | None = None,
    fingerprints: dict[tuple[str, str], str] | None = None,
    chunk_size: int = SEED_CHUNK,
    online_steps: int = ONLINE_STEPS,
    estimator_options: dict[str, Any] | None = None,
) -> list[CellSpec]:
    """All cells, ordered source, then seed chunk, then estimator (so that consecutive cells
    share generated episodes). ``fingerprints`` maps ``(estimator, source label)`` to
    :attr:`CellSpec.estimator_fingerprint`; ``estimator_options`` go to every estimator's
    factory."""
    options = tuple(sorted((estimator_options or {}).items()))
    settings = settings or MetricSettings()
    fingerprints = fingerprints or {}
    cells = []
    for source in sources:
        for chunk in chunk_seeds(seeds, chunk_size):
            for estimator in estimators:
                cells.append(
                    CellSpec(
                        estimator=estimator,
                        source=source,
                        seeds=chunk,
                        settings=settings,
                        estimator_fingerprint=fingerprints.get((estimator, source.label), ""),
                        online_steps=online_steps,
                        estimator_options=options,
                    )
                )
    return cells
