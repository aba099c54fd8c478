"""The accuracy gate: recompute part of the committed leaderboard and compare, seed for seed.

Every metric of the harness is a deterministic function of the code, the scenario and the seed
(fixed seed streams, float64, one torch thread; :mod:`fkn_bench.harness`), so the committed
per-cell results in ``leaderboards/results`` are a regression baseline as they stand.
:func:`run_accuracy_gate` reruns, with the harness, the first ``seeds`` seeds of the first
committed cell of every (estimator, scenario) pair (seeds 0 and 1 by default; the cost is the
per-step overhead of the batched filters, nearly the same for one seed or two) with the committed
metric settings, and compares every deterministic metric with the committed value of the same seed,
within the per-metric tolerance of :data:`TOLERANCES`: exact for the values that are integers
stored as floats (the 0/1 flags ``stability/*`` and ``*/settled``, the count
``consistency/nis_count``), ``|now - committed| <= 1e-12 + 1e-6 |committed|`` for every computed
float metric (RMSEs, error percentiles, settling times, NEES/NIS means: float64 results differ only
by rounding between machines and libraries); NaN equals NaN only.

A seed that diverged in the committed results and diverges now is compared by its stability flags
only (diverged and the reasons): the error values of a run that has blown up grow chaotically, so
rounding (a batch of 2 instead of 20, another CPU) moves them by percents; whether it diverges is
the result. A change in either direction fails: an improvement also means the committed leaderboard
no longer describes the code. The failure message is a table (estimator, scenario, seed, metric,
committed, now, change) and the command that accepts intentional changes (:data:`ACCEPT_COMMAND`:
recompute every cell, rebuild the leaderboards; then commit ``leaderboards/``).

Coverage is automatic: every registered estimator that builds for a named scenario must have
committed cells for it (an estimator whose factory fails there, e.g. learned parameters not
committed, is skipped for that scenario, as ``fkn-bench run --all`` skips it), else the gate
fails for it with the command that adds them (:data:`ADD_COMMAND`). Pass ``exclude`` to leave an
estimator out on purpose. Committed cells whose estimator configuration (fingerprint) or scenario
configuration changed are reported as stale, and committed cells of estimators that are no longer
registered as orphaned; both fail too. Only the gated pairs' cells are read in full (rows and
checksums); of the others, the JSON records (their estimator and scenario). The regeneration of the
leaderboards (``fkn-bench leaderboard``) reads and checks every cell.
"""

from __future__ import annotations

import fnmatch
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from fkn_bench.reporting.leaderboard import REGENERATE_COMMAND, RESULTS_DIR

__all__ = [
    "ACCEPT_COMMAND",
    "ADD_COMMAND",
    "GATE_SEEDS",
    "RESULTS_DIR",
    "TOLERANCES",
    "AccuracyReport",
    "Difference",
    "Tolerance",
    "run_accuracy_gate",
    "tolerance_for",
]

GATE_SEEDS = 2
"""Seeds recomputed per (estimator, scenario) pair: the first ones of its first committed cell."""

ADD_COMMAND = REGENERATE_COMMAND
"""Computes the cells that are missing or whose configuration changed (finished cells are reused)
and rebuilds the leaderboards: the repository's regeneration command."""

ACCEPT_COMMAND = REGENERATE_COMMAND.replace(" --out ", " --rerun --out ")
"""Accepts intentional changes: recomputes every cell (``--rerun``: a code change that keeps an
estimator's configuration does not change its cells' keys, so resuming would keep the old numbers)
and rebuilds the leaderboards. Run from the repository root, then commit ``leaderboards/``."""


@dataclass(frozen=True)
class Tolerance:
    """``|now - committed| <= absolute + relative * |committed|``; NaN matches only NaN."""

    relative: float
    absolute: float

    def allows(self, committed: float, now: float) -> bool:
        if math.isnan(committed) or math.isnan(now):
            return math.isnan(committed) and math.isnan(now)
        if math.isinf(committed) or math.isinf(now):
            return committed == now
        return abs(now - committed) <= self.absolute + self.relative * abs(committed)

    def __str__(self) -> str:
        if self.relative == 0 and self.absolute == 0:
            return "exact"
        return f"{self.absolute:g} + {self.relative:g} rel"


EXACT = Tolerance(0.0, 0.0)
FLOAT = Tolerance(1e-6, 1e-12)

TOLERANCES: tuple[tuple[str, Tolerance], ...] = (
    ("stability/*", EXACT),
    ("*/settled", EXACT),
    ("consistency/nis_count", EXACT),
    ("*", FLOAT),
)
"""``(group/metric pattern, tolerance)``, first match wins (see module docstring)."""


def tolerance_for(group: str, metric: str, tolerances: Sequence[tuple[str, Tolerance]] = TOLERANCES) -> Tolerance:
    """The tolerance of metric ``group/metric``."""
    for pattern, tolerance in tolerances:
        if fnmatch.fnmatchcase(f"{group}/{metric}", pattern):
            return tolerance
    return FLOAT


_HIGHER_IS_BETTER = ("*/settled",)
_NEUTRAL = ("consistency/*", "*/settling_band")


@dataclass(frozen=True)
class Difference:
    """One metric of one seed outside its tolerance (``now`` or ``committed`` NaN when absent)."""

    estimator: str
    scenario: str
    seed: int
    group: str
    metric: str
    committed: float
    now: float
    tolerance: Tolerance
    note: str = ""

    @property
    def name(self) -> str:
        return f"{self.group}/{self.metric}"

    @property
    def change(self) -> str:
        """Relative change as text (``+12.3%``), or what happened to a missing value."""
        if self.note:
            return self.note
        if math.isnan(self.committed) != math.isnan(self.now):
            return "now NaN" if math.isnan(self.now) else "was NaN"
        if self.committed == 0:
            return f"{self.now - self.committed:+.3g} (abs)"
        return f"{100.0 * (self.now - self.committed) / abs(self.committed):+.4g}%"

    @property
    def verdict(self) -> str:
        """``worse``, ``better`` or ``changed`` (lower is better but for flags of success and
        consistency statistics, which are only ``changed``)."""
        if any(fnmatch.fnmatchcase(self.name, p) for p in _NEUTRAL) or self.note:
            return "changed"
        if math.isnan(self.now) or math.isnan(self.committed):
            return "worse" if math.isnan(self.now) else "changed"
        higher = any(fnmatch.fnmatchcase(self.name, p) for p in _HIGHER_IS_BETTER)
        worse = self.now < self.committed if higher else self.now > self.committed
        return "worse" if worse else "better"


@dataclass(frozen=True)
class PairProblem:
    """A pair (or estimator) that could not be compared: ``kind`` is ``missing`` (no committed
    cells), ``stale`` (the committed cells were made with another estimator or scenario
    configuration), ``orphaned`` (committed cells of an estimator that is not registered) or
    ``failed`` (the recomputed cell failed)."""

    estimator: str
    scenario: str
    kind: str
    detail: str


@dataclass
class AccuracyReport:
    """Outcome of :func:`run_accuracy_gate`."""

    results_dir: str
    seeds: int
    compared: list[tuple[str, str, tuple[int, ...]]] = field(default_factory=list)
    differences: list[Difference] = field(default_factory=list)
    problems: list[PairProblem] = field(default_factory=list)
    skipped: list[tuple[str, str, str]] = field(default_factory=list)
    excluded: dict[str, str] = field(default_factory=dict)
    compared_values: int = 0

    def differences_of(self, estimator: str | None = None) -> list[Difference]:
        return [d for d in self.differences if estimator is None or d.estimator == estimator]

    def problems_of(self, estimator: str | None = None) -> list[PairProblem]:
        return [p for p in self.problems if estimator is None or p.estimator == estimator]

    def passed(self, estimator: str | None = None) -> bool:
        return not self.differences_of(estimator) and not self.problems_of(estimator)

    def table(self, estimator: str | None = None, *, limit: int = 60) -> str:
        """The differences as an aligned text table (at most ``limit`` rows, worst first within
        each pair)."""
        from fkn_bench.reporting.report import text_table

        rows = self.differences_of(estimator)
        if not rows:
            return "(no differences)"
        header = ("estimator", "scenario", "seed", "metric", "committed", "now", "change", "verdict", "tolerance")
        body = [
            (d.estimator, d.scenario, str(d.seed), d.name, _number(d.committed), _number(d.now), d.change, d.verdict,
             str(d.tolerance))
            for d in rows[:limit]
        ]
        lines = [text_table(header, body, right={2, 4, 5, 6})]
        if len(rows) > limit:
            lines.append(f"... and {len(rows) - limit} more differences")
        return "\n".join(lines)

    def message(self, estimator: str | None = None) -> str:
        """Readable failure text: problems, the difference table and what to do."""
        parts = [f"{p.kind}: {p.estimator} on {p.scenario}: {p.detail}" for p in self.problems_of(estimator)]
        differences = self.differences_of(estimator)
        if differences:
            pairs = sorted({(d.estimator, d.scenario) for d in differences})
            parts.append(
                f"{len(differences)} metric values differ from the committed results in {self.results_dir} "
                f"beyond tolerance ({len(pairs)} estimator x scenario pairs, seeds recomputed: {self.seeds} per pair):"
            )
            parts.append(self.table(estimator))
        if parts:
            parts.append(
                "If the change is intended, accept it (from the repository root) and commit leaderboards/:\n"
                f"    {ACCEPT_COMMAND}\n"
                f"(only missing or reconfigured cells: {ADD_COMMAND})"
            )
        return "\n".join(parts) if parts else "accuracy gate passed"

    def summary(self) -> str:
        pairs = len(self.compared)
        verdict = "passed" if self.passed() else "FAILED"
        text = (f"accuracy gate {verdict}: {pairs} estimator x scenario pairs, {self.compared_values} values compared, "
                f"{len(self.differences)} differences, {len(self.problems)} problems")
        if self.excluded:
            text += f"; excluded: {', '.join(sorted(self.excluded))}"
        return text


def _number(value: float) -> str:
    return "NaN" if math.isnan(value) else f"{value:.10g}"


def _committed_rows(records: Iterable[Any], seeds: Mapping[tuple[str, str], tuple[int, ...]]) -> pd.DataFrame:
    from fkn_bench.harness.rows import deterministic_rows

    frames = []
    for record in records:
        wanted = seeds.get((record.estimator, record.scenario))
        if wanted is None:
            continue
        rows = record.rows[record.rows["seed"].isin(wanted)]
        if len(rows):
            frames.append(rows)
    if not frames:
        return pd.DataFrame(columns=["estimator", "scenario", "seed", "group", "metric", "value", "unit"])
    return deterministic_rows(pd.concat(frames, ignore_index=True))


def _committed_cells(results_dir: str | Path, gated: set[tuple[str, str]]) -> tuple[Any, list[str]]:
    """``(results, names)``: the committed cells of the ``gated`` ``(estimator label, scenario)``
    pairs as :class:`~fkn_bench.harness.Results` (read and checksummed as
    :meth:`~fkn_bench.harness.ResultStore.load` reads them), and the estimator names of every
    committed cell (a run with options, such as a training-seed replica, counts as its estimator),
    from the cells' JSON records alone: the rows of the pairs not gated (most of the store) are not
    parsed. Raises :class:`~fkn_bench.harness.StoreError` as ``load`` does for
    a missing or empty directory, and for a cell record that cannot be read."""
    from fkn_bench.harness import ResultStore, Results, StoreError
    from fkn_bench.harness.grid import estimator_label
    from fkn_bench.io import read_json

    class _Gated(ResultStore):
        def cell_files(self) -> list[Path]:
            return files

    store = ResultStore(results_dir)
    everything = store.cell_files()
    if not everything:
        store.load()  # raises the store's error (no such directory, no cells)
    labels: dict[Path, tuple[str, str]] = {}
    names = set()
    for path in everything:
        try:
            document = read_json(path)
            labels[path] = (estimator_label(document["estimator"], document["key"].get("estimator_options") or ()),
                            document["scenario"])
            names.add(document["estimator"])
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            raise StoreError(f"{path} is not a readable fkn-bench cell file: {exc}") from None
    files = [path for path in everything if labels[path] in gated]
    results = _Gated(results_dir).load() if files else Results([])
    return results, sorted(names)


def _compare(committed: pd.DataFrame, now: pd.DataFrame, tolerances: Sequence[tuple[str, Tolerance]]) -> tuple[list[Difference], int]:
    keys = ["estimator", "scenario", "seed", "group", "metric"]
    merged = committed[keys + ["value"]].merge(now[keys + ["value"]], on=keys, how="outer",
                                               suffixes=("_committed", "_now"), indicator="side")
    flags = merged[(merged.group == "stability") & (merged.metric == "diverged")]
    diverged = {(r.estimator, r.scenario, r.seed) for r in flags.itertuples(index=False)
                if r.value_committed == 1.0 and r.value_now == 1.0}
    differences = []
    for row in merged.itertuples(index=False):
        if row.group != "stability" and (row.estimator, row.scenario, row.seed) in diverged:
            continue  # a run that diverged then and now: its flags are compared, its chaotic values not
        tolerance = tolerance_for(row.group, row.metric, tolerances)
        before, after = float(row.value_committed), float(row.value_now)
        note = ""
        if row.side == "left_only":
            note = "not computed now"
        elif row.side == "right_only":
            note = "not committed"
        elif tolerance.allows(before, after):
            continue
        differences.append(Difference(row.estimator, row.scenario, int(row.seed), row.group, row.metric, before, after,
                                      tolerance, note))
    differences.sort(key=lambda d: (d.estimator, d.scenario, d.group != "state", d.name, d.seed))
    return differences, len(merged)


def run_accuracy_gate(
    results_dir: str | Path = RESULTS_DIR,
    *,
    seeds: int = GATE_SEEDS,
    estimators: Sequence[str] | None = None,
    scenarios: Sequence[str] | None = None,
    exclude: Mapping[str, str] | None = None,
    scenarios_of: Mapping[str, Sequence[str]] | None = None,
    tolerances: Sequence[tuple[str, Tolerance]] = TOLERANCES,
) -> AccuracyReport:
    """Run the gate (module docstring) against the committed results in ``results_dir``.

    Args:
        results_dir: a results directory written by ``fkn-bench run --out``.
        seeds: seeds recomputed per pair (the first ones of the pair's first committed cell).
        estimators: estimators to gate (default: every registered one).
        scenarios: scenarios to gate (default: every named scenario).
        exclude: estimators left out on purpose, ``{name: reason}``.
        scenarios_of: ``{name: scenarios}``: gate these estimators on these scenarios only (of
            ``scenarios``), e.g. a combination of a filter variant and a process model whose two
            parts are gated on every scenario by other estimators; the other pairs are listed in
            ``skipped``.
        tolerances: ``(group/metric pattern, Tolerance)``, first match wins.
    """
    from fkn_bench.estimators import estimator_names
    from fkn_bench.harness import MetricSettings, SimulatedSource, run_grid
    from fkn_bench.harness.estimators import resolve_estimator
    from fkn_bench.harness.grid import CellSpec
    from fkn_bench.scenarios import get_scenario, scenario_names

    if seeds < 1:
        raise ValueError(f"seeds must be >= 1 (got {seeds})")
    exclude = dict(exclude or {})
    registered = estimator_names()
    names = [n for n in (estimators if estimators is not None else registered) if n not in exclude]
    scenario_list = list(scenarios) if scenarios is not None else list(scenario_names())
    scenarios_of = {name: set(only) for name, only in (scenarios_of or {}).items()}
    gated = {(name, scenario) for scenario in scenario_list for name in names
             if name not in scenarios_of or scenario in scenarios_of[name]}
    committed, committed_labels = _committed_cells(results_dir, gated)
    report = AccuracyReport(results_dir=str(results_dir), seeds=seeds, excluded=exclude)

    def problem(name: str, scenario: str, kind: str, detail: str) -> None:
        report.problems.append(PairProblem(name, scenario, kind, detail))

    if estimators is None:
        for name in sorted(set(committed_labels) - set(registered) - set(exclude)):
            problem(name, "*", "orphaned", f"committed cells but no such estimator is registered: remove "
                    f"{results_dir}/cells/{name} and rebuild the leaderboards (fkn-bench leaderboard)")

    cells: list[CellSpec] = []
    wanted: dict[tuple[str, str], tuple[int, ...]] = {}
    for scenario_name in scenario_list:
        scenario = get_scenario(scenario_name)
        for name in names:
            if name in scenarios_of and scenario_name not in scenarios_of[name]:
                report.skipped.append((name, scenario_name, "not gated on this scenario (scenarios_of)"))
                continue
            records = committed.cells(name, scenario_name)
            resolved = resolve_estimator(name, scenario)
            if not resolved.available:
                if records:
                    problem(name, scenario_name, "stale",
                            f"committed cells exist but the estimator no longer builds ({resolved.error})")
                else:
                    report.skipped.append((name, scenario_name, resolved.error or "unavailable"))
                continue
            if not records:
                problem(name, scenario_name, "missing",
                        f"no committed results in {results_dir}; add them with `{ADD_COMMAND}` and commit "
                        "leaderboards/ (or exclude the estimator from the gate on purpose)")
                continue
            first = records[0]
            source = SimulatedSource(scenario, first.source.get("split", "test"))
            key = first.key
            if key.get("estimator_fingerprint") != resolved.fingerprint:
                problem(name, scenario_name, "stale", "the estimator's configuration changed (fingerprint "
                        f"{key.get('estimator_fingerprint')} committed, {resolved.fingerprint} now): accept with "
                        f"`{ACCEPT_COMMAND}`")
            if key.get("source") != source.key():
                problem(name, scenario_name, "stale", f"the scenario changed ({key.get('source')} committed, "
                        f"{source.key()} now): accept with `{ACCEPT_COMMAND}`")
            gate_seeds = tuple(first.seeds[:seeds])
            wanted[(name, scenario_name)] = gate_seeds
            cells.append(CellSpec(resolved, source, gate_seeds, MetricSettings.from_dict(key["settings"]),
                                  online_steps=1))  # the online timing is cost, not accuracy
            report.compared.append((name, scenario_name, gate_seeds))

    if cells:
        outcome = run_grid(cells, progress=False)
        for record in outcome.results.records:
            if record.status != "ok":
                committed_failed = any(r.status != "ok" for r in committed.cells(record.estimator, record.scenario))
                if not committed_failed:
                    problem(record.estimator, record.scenario, "failed", f"the estimator raised: {record.error}")
        now_rows = _committed_rows(outcome.results.records, wanted)
        then_rows = _committed_rows(committed.records, wanted)
        report.differences, report.compared_values = _compare(then_rows, now_rows, tolerances)
    return report
