"""Search spaces for hyperparameter sweeps, read from TOML.

A space file names the knobs to search (``[params.<config field>]`` tables), the values every
trial holds fixed (``[fixed]``) and, optionally, defaults for the command line (``[sweep]``)::

    [sweep]                     # optional; command-line options override these
    estimator = "flexkalmannet"
    scenario = "ds1"
    sampler = "random-grid"     # random-grid | random | grid | tpe
    trials = 40                 # trials of the random (or only) stage
    grid_trials = 16            # random-grid: most grid points of the second stage
    top_k = 4                   # random-grid: best random trials that span the reduced grid
    seed = 0

    [sweep.pruner]              # optional; default: median, 3 startup trials, 2 warm-up epochs
    kind = "median"             # median | percentile | hyperband | none
    n_startup_trials = 3
    n_warmup_steps = 2
    # percentile = 25.0         (kind = "percentile")

    [fixed]                     # config fields held by every trial
    epochs = 30

    [params.hidden]             # categorical: a list of values (numbers, strings, booleans)
    values = [64, 128, 256, 512]

    [params.layers]             # integer range (low and high are integers), inclusive
    low = 2
    high = 7

    [params.lr]                 # float range; log = true samples log-uniformly
    low = 1e-5
    high = 1e-2
    log = true
    grid = [1e-5, 1e-4, 1e-3, 1e-2]   # values for the grid sampler (or grid_points = 4)

Knob names are fields of the estimator's configuration (for ``flexkalmannet``,
:class:`~fkn_bench.flexkalmannet.FlexKalmanNetConfig`: ``hidden``, ``layers``, ``lr``,
``window``, ``windows_per_batch``, ``loss_cut``, ``dropout``, ``weight_decay``, ``activation``,
``variant``, ``objective``, ...). A range knob takes ``type = "int"`` or ``"float"`` to override
the type its bounds imply, ``step`` for a discretised range (not with ``log``), and for the grid
sampler either an explicit ``grid`` list or ``grid_points = N`` (evenly spaced, geometrically when
``log``); an integer range without them is enumerated when it has at most
:data:`MAX_ENUMERATED` values. Tuple-valued fields (``learn``) take comma-separated strings
(``values = ["q_std,r_std", "q_chol,r_std"]``).

Numbers are TOML numbers: a bound, a grid point or a ``[sweep]`` count given as a string or a
boolean is refused, and so is a ``[fixed]`` value or a knob's value that is not of the kind of the
configuration field it sets (:meth:`SearchSpace.check_kinds`, e.g. ``lr = "0.1"``, ``hidden =
8.5``). Errors (:class:`SpaceError`) name the file, the knob and what is wrong.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # optuna is imported where a space is used, not where its names are listed
    import optuna
    from optuna.distributions import BaseDistribution

__all__ = [
    "SpaceError",
    "Knob",
    "PrunerSpec",
    "SearchSpace",
    "SAMPLERS",
    "PRUNERS",
    "MAX_ENUMERATED",
    "check_sweep_options",
    "parse_space",
    "load_space",
    "packaged_spaces",
    "resolve_space",
]

SAMPLERS = ("random-grid", "random", "grid", "tpe")
"""Sampling methods: the paper's random search then grid search over the reduced space
(``random-grid``), or one of random search, grid search and TPE alone."""
PRUNERS = ("median", "percentile", "hyperband", "none")
MAX_ENUMERATED = 64
"""Largest integer range the grid sampler enumerates without an explicit ``grid``."""

_SWEEP_KEYS = {"estimator", "scenario", "sampler", "trials", "grid_trials", "top_k", "seed", "pruner"}
_PRUNER_INTEGERS = {"n_startup_trials": 0, "n_warmup_steps": 0, "min_resource": 1, "reduction_factor": 2}
_PRUNER_KEYS = {"kind", "percentile", *_PRUNER_INTEGERS}
_KNOB_KEYS = {"values", "low", "high", "log", "step", "type", "grid", "grid_points"}
_SPACES_DIR = Path(__file__).with_name("spaces")


class SpaceError(ValueError):
    """An invalid search space (the message names the file and the knob)."""


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _of_kind(value: Any, kind: str) -> int | float | None:
    """``value`` as a number of ``kind`` (int or float); None when it is not one."""
    if not _is_number(value) or (kind == "int" and not float(value).is_integer()):
        return None
    return int(value) if kind == "int" else float(value)


@dataclass(frozen=True)
class Knob:
    """One searched hyperparameter: the configuration field ``name`` and its ``[params.<name>]``
    table (module docstring), of ``kind`` ``categorical``, ``int`` or ``float``. A range without
    ``step`` is continuous (floats) or has step 1 (integers)."""

    name: str
    kind: str
    values: tuple[Any, ...] = ()
    low: float | int | None = None
    high: float | int | None = None
    log: bool = False
    step: float | int | None = None
    grid: tuple[Any, ...] = ()
    grid_points: int | None = None

    def distribution(self) -> BaseDistribution:
        """The optuna distribution of the knob (the same in every stage of a sweep)."""
        from optuna.distributions import CategoricalDistribution, FloatDistribution, IntDistribution

        if self.kind == "categorical":
            return CategoricalDistribution(self.values)
        low, high = self.low, self.high
        assert low is not None and high is not None
        if self.kind == "int":
            return IntDistribution(int(low), int(high), log=self.log, step=int(self.step or 1))
        return FloatDistribution(float(low), float(high), log=self.log, step=self.step)

    def suggest(self, trial: optuna.Trial) -> Any:
        """Ask ``trial`` for a value of :meth:`distribution` (the sampler decides which)."""
        from optuna.distributions import CategoricalDistribution, IntDistribution

        d = self.distribution()
        if isinstance(d, CategoricalDistribution):
            return trial.suggest_categorical(self.name, list(d.choices))
        suggest = trial.suggest_int if isinstance(d, IntDistribution) else trial.suggest_float
        return suggest(self.name, d.low, d.high, log=d.log, step=d.step)  # type: ignore[operator]

    def contains(self, value: Any) -> bool:
        distribution = self.distribution()
        try:
            return bool(distribution._contains(distribution.to_internal_repr(value)))
        except (ValueError, TypeError):
            return False

    def grid_values(self, source: str = "<space>") -> tuple[Any, ...]:
        """Candidates of the grid sampler (see module docstring)."""
        if self.kind == "categorical" or self.grid:
            return self.values or self.grid
        low, high = self.low, self.high
        assert low is not None and high is not None
        if self.grid_points is not None:
            n = self.grid_points
            if self.log:
                points = [math.exp(math.log(low) + i * (math.log(high) - math.log(low)) / (n - 1)) for i in range(n)]
            else:
                points = [low + i * (high - low) / (n - 1) for i in range(n)]
            if self.kind == "int":
                return tuple(sorted({int(round(p)) for p in points}))
            return tuple(float(f"{p:.6g}") for p in points)
        hint = "give `grid = [...]` or `grid_points = N` for the grid sampler"
        if self.kind == "int":
            values = tuple(range(int(low), int(high) + 1, int(self.step or 1)))
            if len(values) <= MAX_ENUMERATED:
                return values
            raise SpaceError(f"{source}: [params.{self.name}] has {len(values)} integer values: {hint}")
        if self.step is not None:
            count = int(round((high - low) / self.step)) + 1
            if count <= MAX_ENUMERATED:
                return tuple(float(f"{low + i * self.step:.12g}") for i in range(count))
        raise SpaceError(f"{source}: [params.{self.name}] is a continuous range: {hint}")

    def to_dict(self) -> dict[str, Any]:
        if self.kind == "categorical":
            return {"kind": self.kind, "values": list(self.values)}
        optional = {"step": self.step, "grid": list(self.grid) or None, "grid_points": self.grid_points}
        return {"kind": self.kind, "low": self.low, "high": self.high, "log": self.log,
                **{k: v for k, v in optional.items() if v is not None}}


@dataclass(frozen=True)
class PrunerSpec:
    """Which optuna pruner stops unpromising trials early (on the reported validation losses)."""

    kind: str = "median"
    n_startup_trials: int = 3
    n_warmup_steps: int = 2
    percentile: float = 25.0
    min_resource: int = 1
    reduction_factor: int = 3

    def make(self) -> optuna.pruners.BasePruner:
        import optuna

        if self.kind == "median":
            return optuna.pruners.MedianPruner(n_startup_trials=self.n_startup_trials, n_warmup_steps=self.n_warmup_steps)
        if self.kind == "percentile":
            return optuna.pruners.PercentilePruner(self.percentile, n_startup_trials=self.n_startup_trials,
                                                   n_warmup_steps=self.n_warmup_steps)
        if self.kind == "hyperband":
            return optuna.pruners.HyperbandPruner(min_resource=self.min_resource, reduction_factor=self.reduction_factor)
        return optuna.pruners.NopPruner()


@dataclass(frozen=True)
class SearchSpace:
    """A parsed search space (module docstring): the ``knobs`` in file order, the ``[fixed]``
    values, the ``[sweep]`` table's command-line ``defaults`` (``pruner`` excluded), the ``pruner``
    and the ``source`` that messages name."""

    knobs: tuple[Knob, ...]
    fixed: dict[str, Any] = field(default_factory=dict)
    defaults: dict[str, Any] = field(default_factory=dict)
    pruner: PrunerSpec = field(default_factory=PrunerSpec)
    source: str = "<space>"

    @property
    def names(self) -> list[str]:
        return [k.name for k in self.knobs]

    def distributions(self) -> dict[str, BaseDistribution]:
        return {k.name: k.distribution() for k in self.knobs}

    def grid(self) -> dict[str, list[Any]]:
        """The full grid (every knob's :meth:`Knob.grid_values`)."""
        return {k.name: list(k.grid_values(self.source)) for k in self.knobs}

    def suggest(self, trial: optuna.Trial) -> dict[str, Any]:
        """Every knob's value for ``trial``."""
        return {k.name: k.suggest(trial) for k in self.knobs}

    def check_fields(self, fields: Iterable[str], what: str) -> None:
        """Raise :class:`SpaceError` unless every knob and fixed key is one of ``fields``."""
        valid = set(fields)
        unknown = [n for n in self.names if n not in valid] + [n for n in self.fixed if n not in valid]
        _require(not unknown, f"{self.source}: unknown {what} field(s) {', '.join(unknown)}; "
                              f"valid: {', '.join(sorted(valid))}")

    def check_kinds(self, annotations: Mapping[str, Any]) -> None:
        """Raise :class:`SpaceError` naming the file and the table unless every ``[fixed]`` value
        and every value a knob can take (its ``values``, bounds and ``grid``) is of the kind of the
        configuration field it sets (``annotations``: field name to type;
        :mod:`fkn_bench.config_values`: e.g. a number, never ``true`` or ``"0.1"``)."""
        from fkn_bench.config_values import accepts, describe_kind

        for key, value in self.fixed.items():
            kind = annotations.get(key)
            _require(kind is None or accepts(kind, value),
                     f"{self.source}: [fixed] {key} must be {describe_kind(kind)} (got {value!r})")
        for knob in self.knobs:
            kind = annotations.get(knob.name)
            for value in knob.values or (knob.low, knob.high, *knob.grid):
                _require(kind is None or accepts(kind, value),
                         f"{self.source}: [params.{knob.name}] value {value!r} is not {describe_kind(kind)}, the kind of "
                         f"{knob.name}")

    def to_dict(self) -> dict[str, Any]:
        return {
            "params": {k.name: k.to_dict() for k in self.knobs},
            "fixed": dict(self.fixed),
            "pruner": dataclasses.asdict(self.pruner),
        }

    def fingerprint(self) -> str:
        """Short hash of the knobs, fixed values and pruner (a study refuses a different space)."""
        return hashlib.sha256(json.dumps(self.to_dict(), sort_keys=True, default=str).encode()).hexdigest()[:16]


def _require(ok: Any, message: str) -> None:
    """Raise :class:`SpaceError` with ``message`` unless ``ok``."""
    if not ok:
        raise SpaceError(message)


def _known_keys(table: Mapping[str, Any], valid: set[str], where: str) -> None:
    unknown = sorted(set(table) - valid)
    _require(not unknown, f"{where}: unknown key(s) {', '.join(unknown)}; valid: {', '.join(sorted(valid))}")


def _parse_knob(name: str, table: Any, source: str) -> Knob:
    where = f"{source}: [params.{name}]"
    _require(isinstance(table, dict), f"{where} must be a table with `values` or `low`/`high`")
    _known_keys(table, _KNOB_KEYS, where)
    if "values" in table:
        extra = sorted(set(table) - {"values"})
        _require(not extra, f"{where}: `values` (categorical) cannot be combined with {', '.join(extra)}")
        values = table["values"]
        _require(isinstance(values, list) and values, f"{where}: `values` must be a non-empty list")
        for v in values:
            _require(isinstance(v, (str, int, float, bool)),
                     f"{where}: values must be numbers, strings or booleans (got {v!r})")
        _require(len(set(map(repr, values))) == len(values), f"{where}: `values` has duplicates")
        return Knob(name, "categorical", values=tuple(values))
    _require("low" in table and "high" in table, f"{where} needs `values = [...]` or both `low` and `high`")
    low, high = table["low"], table["high"]
    _require(_is_number(low) and _is_number(high),
             f"{where}: `low` and `high` must be finite numbers (got {low!r}, {high!r})")
    kind = table.get("type", "int" if isinstance(low, int) and isinstance(high, int) else "float")
    _require(kind in ("int", "float"), f"{where}: `type` must be \"int\" or \"float\" (got {kind!r})")
    low, high = _of_kind(low, kind), _of_kind(high, kind)
    _require(low is not None and high is not None,
             f"{where}: an integer range needs integer bounds (got {table['low']!r}, {table['high']!r})")
    _require(low < high, f"{where}: need low < high (got {low!r}, {high!r})")  # type: ignore[operator]
    log = table.get("log", False)
    _require(isinstance(log, bool), f"{where}: `log` must be true or false (got {log!r})")
    _require(not (log and low <= 0), f"{where}: a log range needs low > 0 (got {low!r})")  # type: ignore[operator]
    noun = "integer" if kind == "int" else "number"
    step = table.get("step")
    if step is not None:
        _require(not log, f"{where}: `step` cannot be combined with `log = true`")
        step = _of_kind(step, kind)
        _require(step is not None and step > 0, f"{where}: `step` must be a positive {noun} (got {table['step']!r})")
    grid_points = table.get("grid_points")
    _require(grid_points is None or (isinstance(grid_points, int) and not isinstance(grid_points, bool)
                                     and grid_points >= 2),
             f"{where}: `grid_points` must be an integer >= 2 (got {grid_points!r})")
    grid = table.get("grid", [])
    _require(isinstance(grid, list), f"{where}: `grid` must be a list")
    _require(not (grid and grid_points is not None), f"{where}: give `grid` or `grid_points`, not both")
    knob = Knob(name, kind, low=low, high=high, log=log, step=step, grid_points=grid_points)
    values = [_of_kind(v, kind) for v in grid]
    for v, value in zip(grid, values):
        _require(value is not None, f"{where}: grid value {v!r} is not {'an' if kind == 'int' else 'a'} {noun}")
        _require(knob.contains(value), f"{where}: grid value {value!r} lies outside [{low}, {high}]"
                                       + (f" step {step}" if step else ""))
    _require(len(set(values)) == len(values), f"{where}: `grid` has duplicates")
    return dataclasses.replace(knob, grid=tuple(values)) if grid else knob


def _integer(value: Any, name: str, low: int = 1, error: type[ValueError] = ValueError) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or value < low:
        raise error(f"{name} must be an integer >= {low} (got {value!r})")
    return value


_SWEEP_INTEGERS = {"trials": 1, "grid_trials": 1, "top_k": 1, "workers": 1, "seed": 0}


def check_sweep_options(values: Mapping[str, Any], error: type[ValueError] = ValueError,
                        where: str = "") -> None:
    """Raise ``error`` (message prefixed by ``where``) for an invalid sweep option (``sampler``,
    ``trials``, ``grid_trials``, ``top_k``, ``workers``, ``seed``; None values are left to the
    defaults): the one check of ``[sweep]`` tables and of :class:`~fkn_bench.sweep.SweepSettings`."""
    if values.get("sampler", SAMPLERS[0]) not in SAMPLERS:
        raise error(f"{where}sampler must be one of {', '.join(SAMPLERS)} (got {values['sampler']!r})")
    for key, low in _SWEEP_INTEGERS.items():
        if values.get(key) is not None:
            _integer(values[key], where + key, low, error)


def _parse_pruner(table: Any, source: str) -> PrunerSpec:
    if table is None:
        return PrunerSpec()
    _require(isinstance(table, dict), f"{source}: [sweep.pruner] must be a table")
    _known_keys(table, _PRUNER_KEYS, f"{source}: [sweep.pruner]")
    kind = table.get("kind", "median")
    _require(kind in PRUNERS, f"{source}: [sweep.pruner] kind must be one of {', '.join(PRUNERS)} (got {kind!r})")
    integers = {key: _integer(table[key], f"{source}: [sweep] pruner.{key}", low, SpaceError)
                for key, low in _PRUNER_INTEGERS.items() if key in table}
    p = table.get("percentile", PrunerSpec.percentile)
    _require(_is_number(p) and 0 < p < 100, f"{source}: [sweep.pruner] percentile must be in (0, 100) (got {p!r})")
    return PrunerSpec(kind, percentile=float(p), **integers)


def parse_space(document: Mapping[str, Any], source: str = "<space>") -> SearchSpace:
    """Build a :class:`SearchSpace` from a parsed TOML document (module docstring)."""
    unknown = sorted(set(document) - {"sweep", "fixed", "params"})
    _require(not unknown, f"{source}: unknown table(s) {', '.join(unknown)}; valid: [sweep], [fixed], [params.NAME]")
    params = document.get("params")
    _require(isinstance(params, dict) and params, f"{source}: no knobs to search: add [params.NAME] tables")
    knobs = tuple(_parse_knob(name, table, source) for name, table in params.items())
    fixed = document.get("fixed", {})
    _require(isinstance(fixed, dict), f"{source}: [fixed] must be a table of configuration values")
    both = sorted(set(fixed) & set(params))
    _require(not both, f"{source}: {', '.join(both)} both fixed and searched")
    sweep = document.get("sweep", {})
    _require(isinstance(sweep, dict), f"{source}: [sweep] must be a table")
    _known_keys(sweep, _SWEEP_KEYS, f"{source}: [sweep]")
    defaults = {k: v for k, v in sweep.items() if k != "pruner"}
    check_sweep_options(defaults, SpaceError, f"{source}: [sweep] ")
    for key in ("estimator", "scenario"):
        _require(isinstance(defaults.get(key, ""), str), f"{source}: [sweep] {key} must be a string "
                                                         f"(got {defaults.get(key)!r})")
    return SearchSpace(knobs, dict(fixed), defaults, _parse_pruner(sweep.get("pruner"), source), source)


def load_space(path: str | Path) -> SearchSpace:
    """Read a search-space TOML file."""
    from fkn_bench.io import read_toml

    return parse_space(read_toml(path, "search-space file", SpaceError), str(path))


def packaged_spaces() -> dict[str, Path]:
    """The spaces shipped with fkn-bench (``fkn_bench/sweep/spaces/*.toml``) by name."""
    return {p.stem: p for p in sorted(_SPACES_DIR.glob("*.toml"))}


def resolve_space(text: str | Path) -> Path:
    """A space file path, or the name of a packaged space (``paper``, ``quick``)."""
    path = Path(text)
    if path.is_file():
        return path
    spaces = packaged_spaces()
    if str(text) in spaces:
        return spaces[str(text)]
    raise SpaceError(f"search-space file not found: {text} (packaged spaces: {', '.join(spaces) or 'none'})")
