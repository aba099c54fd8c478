"""The benchmark grid: estimator x source (scenario) x seed chunk.

Seeds are cut into chunks of :data:`SEED_CHUNK` consecutive entries of the seed list (a fixed
function of that list, independent of the backend and worker count). Each chunk is one cell,
filtered as one batch, so the batched computation inside a cell, and hence every metric, is the
same on every backend.

A cell's identity (:meth:`CellSpec.key`) holds everything that changes its numbers; the part of it
that is not the estimator's trained state or the seeds -- the source (scenario, configuration
hash, split), the metric settings (``cut``, ...) and the estimator's options -- is its *variant*
(:func:`variant_id`), so that cells differing only there never share a file, while a retrained
estimator (a new fingerprint) replaces its old cell. Names become file names through
:func:`path_name`, an injective encoding that cannot leave its directory.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from fkn_bench.harness.estimators import ResolvedEstimator, resolve_estimator
from fkn_bench.harness.sources import EpisodeSource
from fkn_bench.limits import ESTIMATION_BYTES_PER_STEP, check_memory
from fkn_bench.metrics import MetricSettings

__all__ = ["SEED_CHUNK", "ONLINE_STEPS", "CellSpec", "chunk_seeds", "build_grid", "path_name",
           "estimator_label", "variant_id"]

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


_PLAIN = re.compile(r"[A-Za-z0-9_.-]")


def path_name(name: str) -> str:
    """``name`` as one path component, injectively: every character outside ``[A-Za-z0-9_.-]``
    (``/``, ``%``, spaces, non-ASCII: each UTF-8 byte) and a leading dot become ``%XX`` (upper-case
    hex), as in URLs. Distinct names give distinct components (``my fast`` -> ``my%20fast``,
    ``my_fast``, ``my/fast`` -> ``my%2Ffast``), and no result is empty, ``.``, ``..`` or holds a
    separator, so a path built from it stays in its directory. Raises ``ValueError`` for an
    empty name."""
    if not name:
        raise ValueError("an empty name cannot be a file name")
    out = []
    for i, char in enumerate(name):
        if _PLAIN.fullmatch(char) and not (i == 0 and char == "."):
            out.append(char)
        else:
            out.extend(f"%{byte:02X}" for byte in char.encode("utf-8"))
    return "".join(out)


def estimator_label(name: str, options: Sequence[Sequence[Any]] = ()) -> str:
    """The name results show for estimator ``name`` run with factory ``options`` (``(key,
    value)`` pairs): the name alone, or ``"manual-ekf (gate=0.5)"`` (values other than strings
    as JSON)."""
    if not options:
        return name
    shown = ", ".join(f"{key}={value if isinstance(value, str) else json.dumps(value)}" for key, value in options)
    return f"{name} ({shown})"


def variant_id(key: Mapping[str, Any]) -> str:
    """12 hex digits of SHA-256 over the variant part of a cell key (:meth:`CellSpec.key`): the
    source key, the metric settings and the estimator options -- not the estimator's name or
    fingerprint, the seeds or the format version (module docstring)."""
    variant = {"source": key.get("source"), "settings": key.get("settings"),
               "estimator_options": key.get("estimator_options") or []}
    text = json.dumps(variant, sort_keys=True, separators=(",", ":"), allow_nan=False, default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:12]


@dataclass(frozen=True)
class CellSpec:
    """One unit of work: filter the seed chunk ``seeds`` of ``source`` with the ``resolved``
    estimator (built once for the source's scenario; an unavailable one makes the cell fail with
    its error), score them with ``settings`` and time an online run of ``online_steps``."""

    resolved: ResolvedEstimator
    source: EpisodeSource
    seeds: tuple[int, ...]
    settings: MetricSettings
    online_steps: int = ONLINE_STEPS

    @property
    def estimator(self) -> str:
        return self.resolved.name

    @property
    def scenario(self) -> str:
        return self.source.label

    @property
    def label(self) -> str:
        """The estimator as results show it: its name and options (:func:`estimator_label`)."""
        return estimator_label(self.estimator, self.resolved.options)

    @property
    def name(self) -> str:
        """Human-readable cell name, e.g. ``manual-ekf/ds1/seeds-0-9`` or
        ``manual-ekf (gate=0.5)/ds1/seeds-0-9``."""
        return f"{self.label}/{self.scenario}/seeds-{self.seeds[0]}-{self.seeds[-1]}"

    def key(self) -> dict[str, Any]:
        """Everything that determines the cell's deterministic results (resume compares it)."""
        options = self.resolved.options
        return {
            "format_version": CELL_FORMAT_VERSION,
            "estimator": self.estimator,
            "estimator_fingerprint": self.resolved.fingerprint,
            **({"estimator_options": [list(item) for item in options]} if options else {}),
            "source": self.source.key(),
            "seeds": list(self.seeds),
            "settings": self.settings.to_dict(),
        }


def _episode_steps(source: EpisodeSource) -> int:
    """Steps of one episode of ``source``: its split of a simulated scenario, else the scenario's."""
    scenario = source.scenario
    split = getattr(source, "split", None)
    if split is not None and split != "full":
        start, stop = scenario.split_bounds()[split]
        return int(stop - start)
    return int(scenario.n_steps)


def build_grid(
    estimators: Sequence[ResolvedEstimator | str],
    sources: Sequence[EpisodeSource],
    seeds: Sequence[int],
    *,
    settings: MetricSettings | None = None,
    chunk_size: int = SEED_CHUNK,
    online_steps: int = ONLINE_STEPS,
) -> list[CellSpec]:
    """All cells, ordered source, then seed chunk, then estimator (so that consecutive cells
    share generated episodes). ``estimators`` are resolved pairs (a source gets the pairs of its
    scenario, :attr:`~EpisodeSource.label`) or names, resolved here once per source."""
    settings = settings or MetricSettings()
    cells = []
    largest_chunk = max((len(chunk) for chunk in chunk_seeds(seeds, chunk_size)), default=0)
    for source in sources:
        steps = _episode_steps(source)
        check_memory(largest_chunk * steps * ESTIMATION_BYTES_PER_STEP,
                     f"a cell of {largest_chunk} sequence(s) of {steps} steps ({source.label})",
                     "fewer steps per episode (the scenario's n_steps, or --cut) or fewer seeds")
        pairs = [resolve_estimator(e, source.scenario) if isinstance(e, str) else e for e in estimators]
        pairs = [p for p in pairs if p.scenario == source.label]
        for chunk in chunk_seeds(seeds, chunk_size):
            cells.extend(CellSpec(p, source, chunk, settings, online_steps) for p in pairs)
    return cells
