"""Leaderboards: per scenario a ranked Markdown table, its HTML page and its CSV, plus an index,
the per-seed CSV of record and a provenance document, all built from stored results.

Ranking: by the primary score, the 13-state RMSE (:data:`fkn_bench.harness.summary.PRIMARY_SCORE`),
mean over seeds, lower is better; equal means by estimator name; estimators without a score (every
run failed) last. Divergence rates, consistency and cost are shown beside it, never folded into
it. The paper's numbers appear as labelled, unranked "(quoted)" rows where they apply
(:mod:`fkn_bench.reporting.reference`).

Statistics (:mod:`fkn_bench.metrics.statistics`): every mean comes with its 95% Student-t
confidence interval over the test episodes (seeds), "n/a" when fewer than two episodes were scored
or one episode's score is not finite. Each ranked estimator is compared with the one ranked above
by a two-sided Wilcoxon signed-rank test on the per-seed scores of the seeds both were scored on
(:func:`tie_tests`); where it cannot separate them at the 5% level (p >= 0.05) the estimator shares
the rank above (:func:`rank_numbers`: ranks 1, 1, 3 ...); where a common seed's score is not
finite there is no test and no tie.

Sections (:func:`scenario_section`): the index leads with the prior families (scenarios tagged
"prior": every episode draws its own truth, episode-disjoint splits), then the paper's fixed-truth
scenarios (the other registered ones: ds1, ds2, their variants, tumble-*), then any other
scenario; each section has its own overview, its estimators ordered by their mean rank in it. A
section without results says so.

Figures (:mod:`fkn_bench.reporting.figures`): for the headline scenarios with results
(:func:`figure_scenarios`: each prior family's headline scenario, then ds1) a comparison chart,
``figures/comparison-<scenario>.png``, drawn from the same summaries as the tables; its PNG text
chunks name the command that draws it (:data:`LEADERBOARD_COMMAND`) and hold the plotted numbers
(:func:`fkn_bench.reporting.plots.comparison_data`) with their SHA-256, so a test recomputes the
fingerprint from the results and finds a figure drawn from other numbers.

Every file is a pure function of the stored results (no dates, no machine facts of the process
that builds it), so rebuilding from the same results gives byte-identical files. The one text
written by people, ``NOTES.md`` in the results directory (:data:`NOTES_FILE`: findings, targets
met and missed, each number with the command that produced it), is copied into the index's
"Notes" section. Layout::

    README.md            index: overview matrix, links, definitions, provenance
    <scenario>.md/.html  ranking, per-component RMSE, consistency and stability
    <scenario>.csv       the ranking table's deterministic columns
    results.csv          per-seed tidy rows of record (cost excluded), sorted
    figures/comparison-<scenario>.png   the headline scenarios' comparison charts
    provenance.json      seeds, settings, scenario hashes, estimator fingerprints, environments
    .fkn-bench-files.json  the files fkn-bench wrote here, with their SHA-256

``<scenario>`` is the name encoded by :func:`fkn_bench.harness.grid.path_name` (the name itself
for the named scenarios). An estimator run with options is its own row, named with them
(``manual-ekf (gate=0.5)``). Results that mix, for one scenario, different data (split, scenario
configuration) or metric settings (``cut``) are refused in one line
(:meth:`~fkn_bench.harness.records.Results.check_comparable`): build such leaderboards from one
results directory per split and cut.

Writing (:func:`write_leaderboards`) follows :mod:`fkn_bench.reporting.manifest`: a file is
replaced only when fkn-bench wrote it (listed in ``.fkn-bench-files.json`` with its SHA-256, and
not edited since; ``figures/`` has its own list) or it already holds the new text; anybody else's
``README.md``, ``results.csv`` or ``figures/comparison-ds1.png`` is refused in one line unless
``force``, before anything is written.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any
from urllib.parse import quote

import numpy as np
import pandas as pd

from fkn_bench.harness.grid import path_name
from fkn_bench.harness.records import Results
from fkn_bench.harness.rows import deterministic_rows
from fkn_bench.harness.store import rows_to_csv
from fkn_bench.harness.summary import GROUP_RMSE_KEYS, summarize_pair
from fkn_bench.io import to_jsonable
from fkn_bench.metrics import DIVERGENCE_REASONS, GROUP_UNITS, GROUPS
from fkn_bench.metrics.statistics import ALPHA, INTERVAL_METHOD, TEST_METHOD, PairedTest, paired_test
from fkn_bench.reporting.bounds import (BOUND_LABEL, BOUND_NOTE, EFFICIENCY_KEYS, bound_means, efficiencies,
                                       format_efficiency, shown_standard_error)
from fkn_bench.reporting.figures import png_bytes
from fkn_bench.reporting.manifest import check_files, write_files
from fkn_bench.reporting.plots import comparison_chart, comparison_data
from fkn_bench.reporting.reference import QuotedRow, quoted_rows
from fkn_bench.reporting.report import format_number, format_percent
from fkn_bench.reporting.tables import Table, html_page, markdown_table
from fkn_bench.types import STATE_NAMES

__all__ = [
    "RESULTS_DIR",
    "REGENERATE_COMMAND",
    "BOUND_COMMAND",
    "LEADERBOARD_COMMAND",
    "CSV_FLOAT_FORMAT",
    "FIGURES_DIR",
    "SECTIONS",
    "rank",
    "tie_tests",
    "rank_numbers",
    "ranked_summaries",
    "scenario_order",
    "scenario_section",
    "figure_scenarios",
    "figure_name",
    "build_leaderboards",
    "build_figures",
    "write_leaderboards",
]

RESULTS_DIR = "leaderboards/results"
"""The committed per-cell results (``fkn-bench run --out``), relative to the repository root."""
LEADERBOARD_COMMAND = "fkn-bench leaderboard"
BOUND_COMMAND = f"fkn-bench bound --results {RESULTS_DIR} --quiet"
"""Computes the posterior Cramér-Rao bound of every simulated scenario of the committed results
that has none stored (or a stale one) and stores it beside the cells (:mod:`fkn_bench.harness.bounds`)."""
REGENERATE_COMMAND = f"fkn-bench run --all --out {RESULTS_DIR} --no-progress && {BOUND_COMMAND} && {LEADERBOARD_COMMAND}"
"""Rebuilds the committed leaderboards: runs every available estimator on every named scenario
(cells already in ``leaderboards/results`` with the same configuration are reused; add
``--rerun`` to recompute them), stores the scenarios' bounds, then rebuilds the tables."""

CSV_FLOAT_FORMAT = "%.10g"
"""Float format of the leaderboard CSVs (fixed, so regenerated files are byte-identical)."""

_DASH = "–"


def _fmt(value: Any, digits: int = 3) -> str:
    text = format_number(value, digits)
    return _DASH if text == "-" else text


def _pct(value: Any) -> str:
    return format_percent(value, _DASH)


def _score(summary: dict[str, Any]) -> float:
    value = summary["state_rmse"]
    return value if value is not None and math.isfinite(value) else math.inf


def rank(summaries: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Summaries sorted by the primary score (ascending), then estimator name."""
    return sorted(summaries, key=lambda s: (_score(s), s["estimator"]))


def _by_seed(summary: dict[str, Any]) -> dict[int, float]:
    return dict(zip(summary["seeds"], summary["state_rmse_by_seed"]))


def tie_tests(ranked: Sequence[dict[str, Any]]) -> list[PairedTest | None]:
    """For each ranked summary, the paired test (:func:`fkn_bench.metrics.statistics.paired_test`)
    of its per-seed scores against the estimator ranked just above; None for the first and for
    estimators without a score (every run failed), which are not ranked."""
    tests: list[PairedTest | None] = [None]
    for above, below in zip(ranked, ranked[1:]):
        scored = math.isfinite(_score(above)) and math.isfinite(_score(below))
        tests.append(paired_test(_by_seed(above), _by_seed(below)) if scored else None)
    return tests[: len(ranked)]


def rank_numbers(ranked: Sequence[dict[str, Any]], tests: Sequence[PairedTest | None]) -> list[int | None]:
    """The rank of each ranked summary: its position, or the rank above when the paired test
    cannot separate the two (``tests[i].tied``); None for estimators without a score."""
    numbers: list[int | None] = []
    for i, (summary, test) in enumerate(zip(ranked, tests)):
        if not math.isfinite(_score(summary)):
            numbers.append(None)
        elif i and test is not None and test.tied and numbers[-1] is not None:
            numbers.append(numbers[-1])
        else:
            numbers.append(i + 1)
    return numbers


def _versus_above(test: PairedTest | None, first: bool) -> str:
    """The ranking table's "vs. above" cell: ``= (p 0.43)`` tied, ``< (p 0.002)`` separated."""
    if first:
        return _DASH
    if test is None or test.pvalue is None:
        return "n/a"
    p = "p < 0.001" if test.pvalue < 0.001 else f"p {test.pvalue:.2g}"
    return f"{'=' if test.tied else '<'} ({p})"


def _with_interval(summary: dict[str, Any]) -> str:
    """``mean [low, high]``: the 13-state RMSE and its 95% interval (``[n/a]`` without one)."""
    ci = summary.get("state_rmse_ci")
    return f"{_fmt(summary['state_rmse'], 4)} " + (f"[{_fmt(ci[0], 4)}, {_fmt(ci[1], 4)}]" if ci else "[n/a]")


def scenario_order(names: Sequence[str]) -> list[str]:
    """Registry order for registered scenarios, then the others alphabetically."""
    from fkn_bench.scenarios import scenario_names

    registered = [n for n in scenario_names() if n in names]
    return registered + sorted(set(names) - set(registered))


SECTIONS: dict[str, tuple[str, str]] = {
    "prior": (
        "Prior families: every episode its own truth",
        "The scenarios tagged `prior` (`fkn-bench scenarios` prints each prior): the forced-spin and free-tumble "
        "families, each a headline scenario with its stress variants. Every episode draws its own truth (angular "
        "rate and axis, drift, position, inertia) from the scenario's prior, and the train, validation and test "
        "splits are disjoint sets of episodes from separate seed streams: no test truth was seen in training. "
        "These are the benchmark's headline.",
    ),
    "paper": (
        "The paper's scenarios: fixed truth, train and test share one trajectory",
        "ds1, ds2 and their variants (ds1-*, tumble-*), after the FlexKalmanNet paper. Their truth is fixed: every "
        "episode shares one angular rate, position and velocity (only the initial attitude and the noise are "
        "drawn per seed), and train, validation and test are three pieces of the same trajectory, so a learned "
        "or tuned estimator is scored on the truth it was fitted to. Kept to compare with the paper, not as the "
        "headline.",
    ),
    "other": (
        "Other scenarios",
        "Scenarios that are not registered in this fkn-bench (e.g. from a scenario file).",
    ),
}
"""The index's sections, in order: ``{key: (heading, description)}`` (:func:`scenario_section`)."""

FIGURES_DIR = "figures"
"""The subdirectory of the leaderboards holding their figures (its own manifest)."""


def scenario_section(results: Results, scenario: str) -> str:
    """The :data:`SECTIONS` key of ``scenario``: ``"prior"`` when its stored configuration (else
    the registry's) is tagged "prior", ``"paper"`` for the other registered scenarios, else
    ``"other"``."""
    from fkn_bench.scenarios import get_scenario, scenario_names

    tags = (results.source(scenario).get("config") or {}).get("tags")
    registered = scenario in scenario_names()
    if tags is None and registered:
        tags = get_scenario(scenario).tags
    if "prior" in (tags or ()):
        return "prior"
    return "paper" if registered else "other"


def figure_scenarios(scenarios: Sequence[str]) -> list[str]:
    """Those of ``scenarios`` whose comparison chart the leaderboards draw: the headline scenario of
    each prior family (:data:`fkn_bench.scenarios.PRIOR_FAMILIES`), then ds1."""
    from fkn_bench.scenarios import PRIOR_FAMILIES

    return [name for name in (*PRIOR_FAMILIES, "ds1") if name in scenarios]


def figure_name(scenario: str) -> str:
    """The comparison chart's file name under :data:`FIGURES_DIR`."""
    return f"comparison-{path_name(scenario)}.png"


def _figure_link(scenario: str) -> str:
    return (f"![{scenario}: 13-state RMSE of every estimator, mean and 95% confidence interval over the test "
            f"episodes, best first]({FIGURES_DIR}/{quote(figure_name(scenario))})")


# ---------------------------------------------------------------------------------------- tables
def _label(summary: dict[str, Any]) -> str:
    """The estimator's row label: its name, what it was trained on, and "non-causal" for a smoother."""
    return (summary["estimator"] + (f" (trained on {summary['trained_on']})" if summary.get("trained_on") else "")
            + (" (non-causal reference)" if summary.get("non_causal") else ""))


def _bound_cell(bound: dict[str, Any], key: str, digits: int = 3) -> str:
    summary = bound["summary"][key]
    return f"{_fmt(summary['mean'], digits)} ±{_fmt(shown_standard_error(summary['mean'], summary['standard_error']), 2)}"


def _ranking_table(ranked: Sequence[dict[str, Any]], quoted: Sequence[QuotedRow], tests: Sequence[PairedTest | None],
                   references: Sequence[dict[str, Any]] = (), bound: dict[str, Any] | None = None) -> Table:
    numbers = rank_numbers(ranked, tests)
    header = [
        "rank", "estimator", "13-state RMSE [95% CI]", "vs. above", "training seeds", "median [IQR]", "efficiency",
        "attitude (deg)",
        "position (m)", "rate (rad/s)",
        "velocity (m/s)", "settling (s)", "settled", "lost track", "NEES flag", "ANEES", "NEES in 95% bounds",
        "µs/step online",
        "µs/step batched",
    ]
    rows = []
    for i, (s, test, number) in enumerate([*zip(ranked, tests, numbers), *((r, None, None) for r in references)]):
        st = s["statistics"]["state_rmse"]
        rows.append([
            _DASH if number is None else str(number),
            _label(s),
            _with_interval(s),
            _versus_above(test, i == 0) if number is not None else _DASH,
            _training_seed_cell(s),
            f"{_fmt(st['median'], 4)} [{_fmt(st['q25'], 3)}, {_fmt(st['q75'], 3)}]",
            format_efficiency(efficiencies(s, bound)["state"]),
            *(_fmt(s[k]) for k in (*GROUP_RMSE_KEYS.values(), "settling_time_s")),
            _pct(s["settled_fraction"]),
            _pct(s.get("lost_track_fraction", s["diverged_fraction"])),
            _pct(s["divergence_reasons"].get("nees_high", float("nan"))),
            _fmt(s["anees"]),
            _pct(s["nees_in_bounds_fraction"]),
            _fmt(s["us_per_step"]),
            _fmt(s["us_per_step_batched"]),
        ])
    if bound is not None:
        rows.append([_DASH, BOUND_LABEL, _bound_cell(bound, "state", 4), _DASH, _DASH, _DASH, "1",
                     *(_bound_cell(bound, g) for g in GROUPS)] + [_DASH] * (len(header) - 11))
    for q in quoted:
        rows.append([_DASH, q.label, f"{_fmt(q.state_rmse, 4)}*"] + [_DASH] * (len(header) - 3))
    runs = sorted({s["runs"] for s in [*ranked, *references]})
    episodes = f"{runs[0]}" if len(runs) == 1 else f"{runs[0]} to {runs[-1]}"
    notes = [
        "13-state RMSE: root of the mean, over the 13 state components [q, r, w, v] and the scored window, of "
        "the squared component errors (quaternion sign-aligned to the truth), per seed; mean over seeds, lower "
        "is better (the primary score). median [IQR]: over seeds. attitude ... velocity: RMSE of the group error "
        "magnitudes (attitude angle, norms of the position, rate and velocity errors).",
        f"Statistics over {episodes} test episodes (seeds) per estimator. [95% CI]: {INTERVAL_METHOD}; n/a where "
        "fewer than two episodes were scored or an episode's score is not finite (see score not finite below). "
        f"vs. above: {TEST_METHOD}. '=': the test cannot separate the estimator from the one ranked above "
        f"(p >= {ALPHA:g}), so it shares that rank; '<': separated; n/a: not tested (no common episode, or a score "
        "that is not finite).",
        "training seeds: the spread over training seeds beside the spread over test episodes: the lowest and "
        "highest mean 13-state RMSE, on the same test episodes, of the parameters that each seed of the estimator's "
        "training-seed study produced (fkn-bench train --seeds; in brackets the number of seeds). The ranked row is "
        "the seed of the median validation RMSE, chosen before any test score was read. Scored on each family's "
        "headline scenarios (the one it is named after, and the tumble scenarios); a dash: trained with one seed, "
        "not trained, or not a headline scenario.",
        "settling: mean over seeds of the time until every group error stays in its band; settled: share of "
        "seeds where every group settled. lost track: share of seeds whose estimate lost the track (NaN, "
        "a failed Cholesky factorisation, or error growth); NEES flag: share of seeds whose NEES stayed above the "
        "99.9% chi-square quantile through the final window (a filter sure of a wrong estimate: consistency, "
        "reported apart; both together are the consistency table's diverged). ANEES: average "
        "NEES of the 12-dim error over seeds and scored steps (12 for a consistent filter); NEES in 95% bounds: "
        "share of steps whose average over the seeds is inside the two-sided 95% chi-square interval. µs/step: "
        "wall time of one online step, and of one sequence step in the batched run (machine-dependent). "
        "(trained on X): the data set a learned or tuned estimator's parameters were fitted to. (non-causal "
        "reference): a smoother, which reads the whole episode before it estimates any step; shown, not ranked.",
    ]
    if bound is not None:
        notes.append(BOUND_NOTE)
    if quoted:
        notes.append(
            "Rows marked (quoted) are copied from the paper, not run here: " + quoted[0].citation + ". "
            "* 13-state RMSE computed from the quoted per-component values; other columns are not reported there."
        )
    return Table("Ranking", header, rows, notes, align=["r", "l"] + ["r"] * (len(header) - 2))


def _components_table(ranked: Sequence[dict[str, Any]], quoted: Sequence[QuotedRow], bound: dict[str, Any] | None = None) -> Table:
    header = ["estimator", *STATE_NAMES]
    rows = [[s["estimator"], *(_fmt(s["rmse"][n]) for n in STATE_NAMES)] for s in ranked]
    if bound is not None:
        rows.append([BOUND_LABEL, *(_fmt(v) for v in np.mean(np.asarray(bound["component_rmse"]), axis=0))])
    rows += [[q.label, *(f"{q.rmse[n]:.3f}" for n in STATE_NAMES)] for q in quoted]
    notes = [
        "RMSE per state component over the scored window, mean over seeds (q: unit quaternion components, "
        "r: m, w: rad/s, v: m/s), the layout of the paper's RMSE table."
    ]
    return Table("RMSE per state component", header, rows, notes)


def covariance_verdict(summary: dict[str, Any]) -> str:
    """What an estimator's error covariance is on a scenario, by its ANEES against the two-sided
    95% bounds: ``"consistent"`` (within), ``"overconfident"`` (above: the errors are larger than
    the covariance says), ``"conservative"`` (below) or ``"none"`` (no covariance reported)."""
    anees = summary.get("anees")
    if anees is None or not math.isfinite(anees):
        return "none"
    lo, hi = summary["anees_bounds"]
    return "overconfident" if anees > hi else "conservative" if anees < lo else "consistent"


def _consistency_table(ranked: Sequence[dict[str, Any]]) -> Table:
    header = ["estimator", "runs", "covariance", "ANEES", "95% bounds", "NEES in bounds", "ANIS", "95% bounds (NIS)",
              "NIS in bounds", "diverged", *DIVERGENCE_REASONS, "failed runs", "score not finite"]
    rows = []
    verdicts: dict[str, list[str]] = {}
    for s in ranked:
        lo, hi = s["anees_bounds"]
        nlo, nhi = s["anis_bounds"]
        verdict = covariance_verdict(s)
        verdicts.setdefault(verdict, []).append(s["estimator"])
        rows.append([
            s["estimator"], str(s["runs"]), verdict, _fmt(s["anees"]), f"[{_fmt(lo)}, {_fmt(hi)}]",
            _pct(s["nees_in_bounds_fraction"]), _fmt(s["anis"]), f"[{_fmt(nlo)}, {_fmt(nhi)}]",
            _pct(s["nis_in_bounds_fraction"]), _pct(s["diverged_fraction"]),
            *(_pct(s["divergence_reasons"][r]) for r in DIVERGENCE_REASONS), str(s["failed_runs"]),
            str(s.get("non_finite_runs", 0)),
        ])
    notes = [
        "NEES on the 12-dim error [dtheta, dr, dw, dv] with the estimator's error covariance; NIS on the 6-dim "
        "pose innovation at update steps. For N runs of a consistent filter N x ANEES ~ chi2(12 N) at each step "
        "(Bar-Shalom, Li & Kirubarajan 2001, sec. 5.4); bounds are the two-sided 95% interval for all runs. "
        "Divergence reasons are shares of runs (a run can have several). score not finite: runs whose 13-state "
        "RMSE is NaN or infinite (a failed run, an estimate that overflowed); they are left out of the means "
        "and IQRs of every table and counted here.",
        "Covariances: " + "; ".join(f"{verdict}: {', '.join(verdicts[verdict])}" for verdict in
                                    ("consistent", "conservative", "overconfident", "none") if verdict in verdicts) + ".",
    ]
    return Table("Consistency and stability", header, rows, notes)


def _settling_table(ranked: Sequence[dict[str, Any]]) -> Table:
    header = ["estimator", *(f"{g} (s)" for g in GROUPS), "all groups (s)", "settled"]
    rows = [
        [s["estimator"], *(_fmt(s["settling_time_by_group_s"][g]) for g in GROUPS), _fmt(s["settling_time_s"]),
         _pct(s["settled_fraction"])]
        for s in ranked
    ]
    notes = [
        "Mean settling time per group over seeds, counted from the first step of the run: the first time after "
        "which the error (centred 10 s moving RMS) stays inside max(tolerance, 2% of its peak) to the end; "
        "tolerances 10 deg, 0.1 m, 0.03 rad/s, 0.005 m/s. Runs that never settle count with the run length."
    ]
    return Table("Settling time", header, rows, notes)


def _efficiency_table(summaries: Sequence[dict[str, Any]], bound: dict[str, Any]) -> Table:
    header = ["estimator", "13-state", *(f"{g}" for g in GROUPS)]
    rows = [[BOUND_LABEL, *(_bound_cell(bound, k, 4 if k == "state" else 3) for k in EFFICIENCY_KEYS)]]
    for s in summaries:
        values = efficiencies(s, bound)
        rows.append([_label(s), *(format_efficiency(values[k]) for k in EFFICIENCY_KEYS)])
    units = ", ".join(f"{g} {GROUP_UNITS[g]}" for g in GROUPS)
    notes = [f"First row: the bound of the 13-state RMSE and of each group's RMSE ({units}), mean over the test "
             "episodes ± Monte-Carlo standard error. Other rows: efficiency = bound / RMSE, the bound averaged over the "
             "episodes the estimator was scored on; 1.0 is the best possible. " + BOUND_NOTE]
    if bound.get("inertia") == "estimated":
        notes.append("The bound of a free tumble with the inertia ratios unknown, their prior the scenario's "
                     "(`fkn-bench bound --scenario NAME --inertia known` prints the bound with the inertia known).")
    return Table("How far from the best possible", header, rows, notes)


# ---------------------------------------------------------------------------------------- pages
def _scenario_intro(results: Results, scenario: str, runs: int) -> list[str]:
    source = results.source(scenario)
    settings = results.settings(scenario)
    seeds = sorted({s for r in results.records if r.scenario == scenario for s in r.seeds})
    seed_text = f"{seeds[0]}..{seeds[-1]}" if seeds == list(range(seeds[0], seeds[-1] + 1)) else ", ".join(map(str, seeds))
    description = (source.get("config") or {}).get("description", "")
    return [
        f"{description}" if description else f"Scenario {scenario}.",
        f"{source.get('split', '?')} split, seeds {seed_text} ({runs} runs per estimator), scored from step "
        f"{settings.cut}; scenario configuration hash {source.get('config_hash', '?')}.",
        f"Regenerate: `{REGENERATE_COMMAND}`.",
    ]


def _summaries(results: Results, scenario: str) -> list[dict[str, Any]]:
    """The summary of every estimator stored for ``scenario`` except the training-seed replicas,
    which become the ``training_seed_rmse`` of their estimator's summary (:func:`_training_seeds`)."""
    estimators = sorted({r.label for r in results.records if r.scenario == scenario and r.training_seed is None})
    summaries = [summarize_pair(results, e, scenario) for e in estimators]
    for summary in summaries:
        _training_seeds(results, summary, scenario)
    return summaries


def _training_seeds(results: Results, summary: dict[str, Any], scenario: str) -> None:
    """Add ``training_seed_rmse`` to ``summary`` when training-seed replicas of its estimator
    (:attr:`~fkn_bench.harness.records.CellRecord.training_seed`) were scored on the same test
    episodes: the mean 13-state RMSE of the committed row (the seed its study chose) and of each
    other training seed, in that order."""
    name, episodes = summary["estimator"], results.seeds(summary["estimator"], scenario)
    replicas = sorted({(r.training_seed, r.label) for r in results.records
                       if r.scenario == scenario and r.estimator == name and r.training_seed is not None})
    values = [summary["state_rmse"]]
    for _, label in replicas:
        if results.seeds(label, scenario) == episodes:
            values.append(summarize_pair(results, label, scenario)["state_rmse"])
    if len(values) > 1:
        summary["training_seed_rmse"] = values


def _training_seed_cell(summary: dict[str, Any]) -> str:
    """``min – max (n)`` of the mean 13-state RMSE over the training seeds (a dash: one seed)."""
    values = summary.get("training_seed_rmse")
    if not values:
        return _DASH
    return f"{_fmt(min(values), 4)} – {_fmt(max(values), 4)} ({len(values)})"


def ranked_and_references(results: Results, scenario: str) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """:func:`ranked_summaries` and :func:`reference_summaries` of ``scenario``, each pair summarised once."""
    summaries = _summaries(results, scenario)
    return (rank([s for s in summaries if not s.get("non_causal")]), rank([s for s in summaries if s.get("non_causal")]))


def ranked_summaries(results: Results, scenario: str) -> list[dict[str, Any]]:
    """The summaries of every causal estimator stored for ``scenario``, ranked (:func:`rank`)."""
    return ranked_and_references(results, scenario)[0]


def reference_summaries(results: Results, scenario: str) -> list[dict[str, Any]]:
    """The summaries of the non-causal estimators (smoothers) stored for ``scenario``, by score:
    shown as references, not ranked (an estimator that reads the whole episode is no filter)."""
    return ranked_and_references(results, scenario)[1]


def _scenario_files(results: Results, scenario: str, ranked: Sequence[dict[str, Any]], tests: Sequence[PairedTest | None],
                    references: Sequence[dict[str, Any]] = (), figure: bool = False) -> dict[str, str]:
    quoted = quoted_rows(scenario)
    bound = results.bounds.get(scenario)
    shown = [*ranked, *references]
    runs = max(s["runs"] for s in shown)
    intro = _scenario_intro(results, scenario, runs)
    tables = [_ranking_table(ranked, quoted, tests, references, bound), _components_table(shown, quoted, bound),
              *([_efficiency_table(shown, bound)] if bound is not None else []), _consistency_table(shown),
              _settling_table(shown)]
    title = f"fkn-bench leaderboard: {scenario}"
    link = [_figure_link(scenario)] if figure else []
    markdown = f"# {title}\n\n" + "\n\n".join([*intro, *link]) + "\n\n" + "\n".join(markdown_table(t) for t in tables)
    page = html_page(title, [p.replace("`", "") for p in intro], tables)
    stem = path_name(scenario)
    return {f"{stem}.md": markdown, f"{stem}.html": page, f"{stem}.csv": _scenario_csv(ranked, tests, references, bound)}


def _scenario_csv(ranked: Sequence[dict[str, Any]], tests: Sequence[PairedTest | None],
                  references: Sequence[dict[str, Any]] = (), bound: dict[str, Any] | None = None) -> str:
    """The ranking's deterministic columns, then the non-causal references (no rank) and the bound
    row (``estimator`` = :data:`BOUND_LABEL`: the bound in the RMSE columns, efficiency 1);
    ``p_vs_above`` rounded to 3 significant digits (the test's decision does not hinge on more, and
    the file stays the same across SciPy versions)."""
    records = []
    numbered = [*zip(ranked, tests, rank_numbers(ranked, tests)), *((r, None, None) for r in references)]
    for s, test, number in numbered:
        st = s["statistics"]["state_rmse"]
        ci = s.get("state_rmse_ci") or (None, None)
        tested = test is not None and test.pvalue is not None
        records.append({
            "rank": number,
            **{k: s[k] for k in ("estimator", "scenario", "runs", "state_rmse")},
            "state_rmse_ci_low": ci[0],
            "state_rmse_ci_high": ci[1],
            "tied_with_above": test.tied if tested else None,
            "p_vs_above": float(f"{test.pvalue:.3g}") if tested else None,
            **{f"state_rmse_{k}": st[k] for k in ("median", "q25", "q75")},
            "training_seeds": len(s.get("training_seed_rmse") or ()) or None,
            "state_rmse_training_seed_min": min(s["training_seed_rmse"]) if s.get("training_seed_rmse") else None,
            "state_rmse_training_seed_max": max(s["training_seed_rmse"]) if s.get("training_seed_rmse") else None,
            **{k: s[k] for k in GROUP_RMSE_KEYS.values()},
            **{f"rmse_{n}": s["rmse"][n] for n in STATE_NAMES},
            **{k: s[k] for k in ("settling_time_s", "settled_fraction", "diverged_fraction", "lost_track_fraction", "anees")},
            "anees_lower": s["anees_bounds"][0],
            "anees_upper": s["anees_bounds"][1],
            "covariance": covariance_verdict(s),
            **{k: s[k] for k in ("nees_in_bounds_fraction", "anis", "nis_in_bounds_fraction")},
            "non_causal": bool(s.get("non_causal")),
            **{f"efficiency_{k}": v for k, v in efficiencies(s, bound).items()},
        })
    if bound is not None:
        means = bound_means(bound)
        components = np.mean(np.asarray(bound["component_rmse"]), axis=0)
        records.append({"estimator": BOUND_LABEL, "scenario": bound["scenario"], "runs": len(bound["seeds"]),
                        "state_rmse": means["state"], **{GROUP_RMSE_KEYS[g]: means[g] for g in GROUPS},
                        **{f"rmse_{n}": float(v) for n, v in zip(STATE_NAMES, components)}, "non_causal": False,
                        **{f"efficiency_{k}": 1.0 for k in EFFICIENCY_KEYS}})
    frame = pd.DataFrame(records)
    frame["rank"] = frame["rank"].astype("Int64")
    frame["training_seeds"] = frame["training_seeds"].astype("Int64")
    frame["tied_with_above"] = frame["tied_with_above"].astype("boolean")
    return rows_to_csv(frame, float_format=CSV_FLOAT_FORMAT)


NOTES_FILE = "NOTES.md"
"""Hand-written notes in a results directory, copied into the leaderboard index."""


def _overview(section: str, scenarios: Sequence[str], ranked: dict[str, list[dict[str, Any]]],
              tests: dict[str, list[PairedTest | None]]) -> Table:
    """The section's overview: estimators (by mean rank over the section's scenarios) x scenarios,
    each cell the mean 13-state RMSE +- its 95% interval's half width; bold: rank 1 (shared)."""
    positions: dict[str, list[int]] = {}
    cells: dict[tuple[str, str], str] = {}
    for scenario in scenarios:
        for position, (summary, number) in enumerate(zip(ranked[scenario], rank_numbers(ranked[scenario], tests[scenario]))):
            positions.setdefault(summary["estimator"], []).append(position)
            text = _fmt(summary["state_rmse"], 4)
            if text != _DASH:
                ci = summary.get("state_rmse_ci")
                text += f" ±{_fmt(ci[1] - summary['state_rmse'], 2)}" if ci else " (CI n/a)"
            cells[(summary["estimator"], scenario)] = f"**{text}**" if number == 1 else text
    estimators = sorted(positions, key=lambda e: (sum(positions[e]) / len(positions[e]), e))
    return Table(
        f"Overview: {SECTIONS[section][0].split(':')[0].lower()}",
        ["estimator", *scenarios], [[e, *(cells.get((e, s), _DASH) for s in scenarios)] for e in estimators],
        notes=["13-state RMSE, mean ± half width of its 95% confidence interval over the test episodes (lower is "
               "better); bold: rank 1, which an estimator shares when the paired test cannot separate it from the "
               "one ranked just above it (a chain of such ties from the first); estimators by their mean rank over "
               "this section's scenarios; – : not run."],
    )


TRAINING_SEEDS_HEADING = "Training seeds"
"""The index's section that gathers every trained estimator's spread over training seeds."""


def _training_seed_overview(scenarios: Sequence[str], ranked: dict[str, list[dict[str, Any]]]) -> Table | None:
    """Every trained estimator (a row labelled "trained on"; by name) x every scenario of
    ``scenarios`` (in that order) where training seeds were scored, i.e. the family headline
    scenarios (:func:`fkn_bench.harness.estimators.family_headline`): the mean 13-state RMSE of the
    committed seed and, in brackets, the lowest and highest over its training seeds (a value alone:
    one seed). None where no scenario has training-seed replicas."""
    columns = [s for s in scenarios if any(r.get("training_seed_rmse") for r in ranked[s])]
    if not columns:
        return None
    cells: dict[tuple[str, str], str] = {}
    for scenario in columns:
        for summary in ranked[scenario]:
            if not summary.get("trained_on"):
                continue
            text, spread = _fmt(summary["state_rmse"], 4), summary.get("training_seed_rmse")
            if spread:
                text += f" ({_fmt(min(spread), 4)}-{_fmt(max(spread), 4)})"
            cells[(summary["estimator"], scenario)] = text
    estimators = sorted({e for e, _ in cells})
    return Table(
        "Spread over training seeds",
        ["estimator", *(f"`{s}`" for s in columns)],
        [[e, *(cells.get((e, s), _DASH) for s in columns)] for e in estimators],
        notes=["Mean 13-state RMSE of the committed parameters (the median-validation seed of a training-seed "
               "study, `fkn-bench train ... --seeds 0 1 2`) on each family's headline scenario, and in brackets the "
               "lowest and highest over the study's training seeds on the same test episodes; a value alone: "
               "trained with one seed; – : not trained for that family."],
    )


def _episodes(results: Results, scenarios: Sequence[str]) -> str:
    counts = sorted({len(set(results.seeds(e, s))) for s in scenarios for e in results.estimators()
                     if results.cells(e, s)})
    return f"{counts[0]}" if len(counts) == 1 else f"{counts[0]} to {counts[-1]}"


def _section(results: Results, section: str, scenarios: Sequence[str], ranked: dict[str, list[dict[str, Any]]],
             tests: dict[str, list[PairedTest | None]]) -> list[str]:
    heading, description = SECTIONS[section]
    lines = [f"## {heading}", "", description, ""]
    if not scenarios:
        return lines + ["No results for these scenarios in [`results/`](results/) yet.", ""]
    lines += [f"Test episodes (seeds) per estimator and scenario: {_episodes(results, scenarios)}.", "",
              markdown_table(_overview(section, scenarios, ranked, tests), level=3).rstrip("\n"), ""]
    for scenario in figure_scenarios(scenarios):
        lines += [_figure_link(scenario), ""]
    if figure_scenarios(scenarios):
        lines += [f"Charts drawn by `{LEADERBOARD_COMMAND}` from the same results as the tables (bar: mean; line: "
                  "95% confidence interval); each PNG's text chunks hold the numbers it plots and their SHA-256.", ""]
    lines += [
        f"- [{s}]({u}.md) ([HTML]({u}.html), [CSV]({u}.csv)): best {ranked[s][0]['estimator']} "
        f"({_fmt(ranked[s][0]['state_rmse'], 4)}"
        + (f"; {BOUND_LABEL} {_fmt(results.bounds[s]['summary']['state']['mean'], 4)}, efficiency "
           f"{format_efficiency(efficiencies(ranked[s][0], results.bounds[s])['state'])}" if s in results.bounds else "") + ")"
        for s, u in ((s, quote(path_name(s))) for s in scenarios) if ranked[s]
    ]
    return lines + [""]


def _index(results: Results, scenarios: Sequence[str], ranked: dict[str, list[dict[str, Any]]],
           tests: dict[str, list[PairedTest | None]], notes: str | None) -> str:
    sections = {key: [s for s in scenarios if scenario_section(results, s) == key] for key in SECTIONS}
    env_lines = [
        f"- fkn-bench {e.get('fkn_bench')}, commit {e.get('git_commit')}, Python {e.get('python')}, "
        f"numpy {e.get('numpy')}, torch {e.get('torch')}, {(e.get('machine') or {}).get('platform')}"
        for e in _environments(results)
    ]
    settings = results.settings()
    body = [line for key in SECTIONS if key != "other" or sections[key] for line in _section(results, key, sections[key], ranked, tests)]
    seed_table = _training_seed_overview([s for key in SECTIONS for s in sections[key]], ranked)
    if seed_table is not None:
        body += [f"## {TRAINING_SEEDS_HEADING}", "",
                 "A learned or tuned estimator's score is one draw from its training: the seed fixes the network's "
                 "initialisation and the order of the training windows. Each scenario's page shows this spread in "
                 "its `training seeds` column; here it is for every trained estimator at once.", "",
                 markdown_table(seed_table, level=3).rstrip("\n"), ""]
    return "\n".join([
        "# fkn-bench leaderboards",
        "",
        "Every available estimator on every named scenario, scored on the test split over seeds; built by "
        f"`{LEADERBOARD_COMMAND}` from the per-cell results in [`results/`](results/). Regenerate everything "
        "(reusing finished cells; add `--rerun` to recompute them):",
        "",
        "```bash",
        REGENERATE_COMMAND,
        "```",
        "",
        f"Primary score: the 13-state RMSE over the scored window (steps >= {settings.cut}, the paper's loss cut): "
        "the root of the mean over the 13 state components [qw qx qy qz, rx ry rz, wx wy wz, vx vy vz] of the "
        "squared errors, quaternion sign-aligned to the truth, per seed, then the mean over seeds. Divergence "
        "rates, consistency (ANEES) and cost are reported beside it on each scenario's page.",
        "",
        f"Statistics: each mean comes with its {INTERVAL_METHOD}; n/a where an episode's score is not finite. "
        f"Adjacent ranks are compared by a {TEST_METHOD}; an estimator the test cannot separate from the one above "
        "shares its rank (no test, and no tie, where a score is not finite). Estimators are ranked within each "
        "section.",
        "",
        *body,
        *(["## Notes", "", f"(From [`results/{NOTES_FILE}`](results/{NOTES_FILE}), written by people; every number "
           "comes with the command that produced it.)", "", notes.strip(), ""] if notes else []),
        "## Files",
        "",
        "- `<scenario>.md` / `.html`: ranking with 95% confidence intervals and paired tests, RMSE per component "
        "(with the paper's quoted rows on ds1), consistency and stability, settling times.",
        "- `<scenario>.csv`: the ranking's deterministic columns.",
        f"- `{FIGURES_DIR}/comparison-<scenario>.png`: the headline scenarios' charts, drawn by `{LEADERBOARD_COMMAND}`.",
        "- `results.csv`: the CSV of record, one row per estimator x scenario x seed x metric (cost excluded).",
        "- `provenance.json`: seeds, metric settings, scenario hashes, estimator fingerprints and the software "
        "and machines that produced the results.",
        "",
        "## Produced with",
        "",
        *env_lines,
        "",
    ])


def _environments(results: Results) -> list[dict[str, Any]]:
    seen: dict[str, dict[str, Any]] = {}
    for record in results.records:
        key = json.dumps(to_jsonable(record.provenance), sort_keys=True)
        seen.setdefault(key, record.provenance)
    return [seen[k] for k in sorted(seen)]


def _provenance(results: Results, scenarios: Sequence[str]) -> str:
    document = {
        "format": "fkn-bench-leaderboard",
        "regenerate": REGENERATE_COMMAND,
        "settings": results.settings().to_dict(),
        "scenarios": {
            s: {
                "config_hash": results.source(s).get("config_hash"),
                "split": results.source(s).get("split"),
                "seeds": sorted({x for r in results.records if r.scenario == s for x in r.seeds}),
            }
            for s in scenarios
        },
        "estimators": {
            e: sorted({r.key.get("estimator_fingerprint", "") for r in results.records if r.label == e})
            for e in results.estimators()
        },
        "cells": len(results),
        "failed_cells": sorted(r.name for r in results.records if r.status != "ok"),
        "environments": _environments(results),
    }
    return json.dumps(to_jsonable(document), indent=2, sort_keys=True) + "\n"


def _ranked(results: Results, scenarios: Sequence[str]) -> dict[str, list[dict[str, Any]]]:
    return {scenario: ranked_summaries(results, scenario) for scenario in scenarios}


def build_leaderboards(results: Results, notes: str | None = None) -> dict[str, str]:
    """Every leaderboard text file as ``{file name: text}`` (see module docstring; the figures:
    :func:`build_figures`); ``notes`` (Markdown) becomes the index's "Notes" section."""
    return _build(results, notes)[0]


def build_figures(results: Results, *, command: str = LEADERBOARD_COMMAND) -> dict[str, bytes]:
    """The comparison charts of :func:`figure_scenarios` as ``{file name: PNG bytes}`` (names under
    :data:`FIGURES_DIR`), each PNG naming ``command`` and holding its plotted numbers
    (:func:`fkn_bench.reporting.figures.png_bytes`)."""
    if not len(results):
        raise ValueError("no results to draw figures from")
    results.check_comparable()
    scenarios = figure_scenarios(scenario_order(results.scenarios()))
    return _figures(_ranked(results, scenarios), scenarios, command)


def _figures(ranked: dict[str, list[dict[str, Any]]], scenarios: Sequence[str], command: str) -> dict[str, bytes]:
    figures = {}
    for scenario in scenarios:
        data = comparison_data(scenario, ranked[scenario], quoted_rows(scenario))
        figures[figure_name(scenario)] = png_bytes(comparison_chart(data), command=command, data=data)
    return figures


def _build(results: Results, notes: str | None, draw: bool = False) -> tuple[dict[str, str], dict[str, bytes]]:
    if not len(results):
        raise ValueError("no results to build leaderboards from")
    results.check_comparable()
    scenarios = scenario_order(results.scenarios())
    drawn = figure_scenarios(scenarios)
    files: dict[str, str] = {}
    both = {scenario: ranked_and_references(results, scenario) for scenario in scenarios}
    ranked = {scenario: both[scenario][0] for scenario in scenarios}
    tests = {scenario: tie_tests(ranked[scenario]) for scenario in scenarios}
    for scenario in scenarios:
        files.update(_scenario_files(results, scenario, ranked[scenario], tests[scenario], both[scenario][1],
                                     figure=scenario in drawn))
    files["README.md"] = _index(results, scenarios, ranked, tests, notes)
    files["results.csv"] = rows_to_csv(deterministic_rows(results.rows), float_format=CSV_FLOAT_FORMAT)
    files["provenance.json"] = _provenance(results, scenarios)
    return files, (_figures(ranked, drawn, LEADERBOARD_COMMAND) if draw else {})


def write_leaderboards(results: Results, out_dir: str | Path, notes: str | None = None, *,
                       force: bool = False) -> list[Path]:
    """Build and write every leaderboard file (atomically) under ``out_dir`` and the figures under
    ``out_dir/figures``, replacing only files fkn-bench wrote there unless ``force`` (module
    docstring); returns the paths. Raises
    :class:`~fkn_bench.reporting.manifest.ForeignFileError` (nothing written) for a file in the way."""
    files, figures = _build(results, notes, draw=True)
    figure_dir = Path(out_dir) / FIGURES_DIR
    check_files(figure_dir, sorted(figures), force=force)  # before any table is written
    paths = write_files(out_dir, files, force=force, what="leaderboards")
    if figures:
        paths += write_files(figure_dir, figures, force=force, what="leaderboard figures")
    return paths
