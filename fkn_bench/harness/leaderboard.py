"""Leaderboards: per scenario a ranked Markdown table, its HTML page and its CSV, plus an index,
the per-seed CSV of record and a provenance document, all built from stored results.

Ranking: by the primary score, the 13-state RMSE (:data:`fkn_bench.harness.summary.PRIMARY_SCORE`),
mean over seeds, lower is better; ties by estimator name; estimators without a score (every run
failed) last. Divergence rates, consistency and cost are
shown beside it, never folded into it. The paper's numbers appear as labelled, unranked
"(quoted)" rows where they apply (:mod:`fkn_bench.harness.reference`).

Every file is a pure function of the stored results (no dates, no machine facts of the process
that builds it), so rebuilding from the same results gives byte-identical files. The one text
written by people, ``NOTES.md`` in the results directory (:data:`NOTES_FILE`: findings, targets
met and missed, each number with the command that produced it), is copied into the index's
"Notes" section. Layout::

    README.md            index: overview matrix, links, definitions, provenance
    <scenario>.md/.html  ranking, per-component RMSE, consistency and stability
    <scenario>.csv       the ranking table's deterministic columns
    results.csv          per-seed tidy rows of record (cost excluded), sorted
    provenance.json      seeds, settings, scenario hashes, estimator fingerprints, environments
    .fkn-bench-files.json  the files fkn-bench wrote here, with their SHA-256

``<scenario>`` is the name encoded by :func:`fkn_bench.harness.grid.path_name` (the name itself
for the named scenarios). An estimator run with options is its own row, named with them
(``manual-ekf (gate=0.5)``). Results that mix, for one scenario, different data (split, scenario
configuration) or metric settings (``cut``) are refused in one line
(:meth:`~fkn_bench.harness.records.Results.check_comparable`): build such leaderboards from one
results directory per split and cut.

Writing (:func:`write_leaderboards`) follows :mod:`fkn_bench.harness.manifest`: a file is
replaced only when fkn-bench wrote it (listed in ``.fkn-bench-files.json`` with its SHA-256, and
not edited since) or it already holds the new text; anybody else's ``README.md`` or
``results.csv`` is refused in one line unless ``force``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any
from urllib.parse import quote

import pandas as pd

from fkn_bench.harness.grid import path_name
from fkn_bench.harness.manifest import write_files
from fkn_bench.harness.records import Results
from fkn_bench.harness.reference import QuotedRow, quoted_rows
from fkn_bench.harness.report import format_number, format_percent
from fkn_bench.harness.rows import deterministic_rows
from fkn_bench.harness.store import rows_to_csv
from fkn_bench.harness.summary import GROUP_RMSE_KEYS, summarize_pair
from fkn_bench.harness.tables import Table, html_page, markdown_table
from fkn_bench.io import to_jsonable
from fkn_bench.metrics import DIVERGENCE_REASONS, GROUPS
from fkn_bench.types import STATE_NAMES

__all__ = [
    "RESULTS_DIR",
    "REGENERATE_COMMAND",
    "LEADERBOARD_COMMAND",
    "CSV_FLOAT_FORMAT",
    "rank",
    "ranked_summaries",
    "scenario_order",
    "build_leaderboards",
    "write_leaderboards",
]

RESULTS_DIR = "leaderboards/results"
"""The committed per-cell results (``fkn-bench run --out``), relative to the repository root."""
LEADERBOARD_COMMAND = "fkn-bench leaderboard"
REGENERATE_COMMAND = f"fkn-bench run --all --seeds 20 --out {RESULTS_DIR} --no-progress && {LEADERBOARD_COMMAND}"
"""Rebuilds the committed leaderboards: runs every available estimator on every named scenario
(cells already in ``leaderboards/results`` with the same configuration are reused; add
``--rerun`` to recompute them), then rebuilds the tables."""

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


def scenario_order(names: Sequence[str]) -> list[str]:
    """Registry order for registered scenarios, then the others alphabetically."""
    from fkn_bench.scenarios import scenario_names

    registered = [n for n in scenario_names() if n in names]
    return registered + sorted(set(names) - set(registered))


# ---------------------------------------------------------------------------------------- tables
def _ranking_table(ranked: Sequence[dict[str, Any]], quoted: Sequence[QuotedRow]) -> Table:
    header = [
        "rank", "estimator", "13-state RMSE", "median [IQR]", "attitude (deg)", "position (m)", "rate (rad/s)",
        "velocity (m/s)", "settling (s)", "settled", "diverged", "ANEES", "NEES in 95% bounds", "µs/step online",
        "µs/step batched",
    ]
    rows = []
    for i, s in enumerate(ranked, start=1):
        st = s["statistics"]["state_rmse"]
        rows.append([
            str(i) if math.isfinite(_score(s)) else _DASH,
            s["estimator"] + (f" (trained on {s['trained_on']})" if s.get("trained_on") else ""),
            _fmt(s["state_rmse"], 4),
            f"{_fmt(st['median'], 4)} [{_fmt(st['q25'], 3)}, {_fmt(st['q75'], 3)}]",
            *(_fmt(s[k]) for k in (*GROUP_RMSE_KEYS.values(), "settling_time_s")),
            _pct(s["settled_fraction"]),
            _pct(s["diverged_fraction"]),
            _fmt(s["anees"]),
            _pct(s["nees_in_bounds_fraction"]),
            _fmt(s["us_per_step"]),
            _fmt(s["us_per_step_batched"]),
        ])
    for q in quoted:
        rows.append([_DASH, q.label, f"{_fmt(q.state_rmse, 4)}*"] + [_DASH] * (len(header) - 3))
    notes = [
        "13-state RMSE: root of the mean, over the 13 state components [q, r, w, v] and the scored window, of "
        "the squared component errors (quaternion sign-aligned to the truth), per seed; mean over seeds, lower "
        "is better (the primary score). median [IQR]: over seeds. attitude ... velocity: RMSE of the group error "
        "magnitudes (attitude angle, norms of the position, rate and velocity errors).",
        "settling: mean over seeds of the time until every group error stays in its band; settled: share of "
        "seeds where every group settled. diverged: share of seeds flagged diverged (NaN, failed Cholesky, "
        "error growth, or NEES above the 99.9% chi-square quantile through the final window). ANEES: average "
        "NEES of the 12-dim error over seeds and scored steps (12 for a consistent filter); NEES in 95% bounds: "
        "share of steps whose average over the seeds is inside the two-sided 95% chi-square interval. µs/step: "
        "wall time of one online step, and of one sequence step in the batched run (machine-dependent). "
        "(trained on X): the data set a learned or tuned estimator's parameters were fitted to.",
    ]
    if quoted:
        notes.append(
            "Rows marked (quoted) are copied from the paper, not run here: " + quoted[0].citation + ". "
            "* 13-state RMSE computed from the quoted per-component values; other columns are not reported there."
        )
    return Table("Ranking", header, rows, notes, align=["r", "l"] + ["r"] * (len(header) - 2))


def _components_table(ranked: Sequence[dict[str, Any]], quoted: Sequence[QuotedRow]) -> Table:
    header = ["estimator", *STATE_NAMES]
    rows = [[s["estimator"], *(_fmt(s["rmse"][n]) for n in STATE_NAMES)] for s in ranked]
    rows += [[q.label, *(f"{q.rmse[n]:.3f}" for n in STATE_NAMES)] for q in quoted]
    notes = [
        "RMSE per state component over the scored window, mean over seeds (q: unit quaternion components, "
        "r: m, w: rad/s, v: m/s), the layout of the paper's RMSE table."
    ]
    return Table("RMSE per state component", header, rows, notes)


def _consistency_table(ranked: Sequence[dict[str, Any]]) -> Table:
    header = ["estimator", "runs", "ANEES", "95% bounds", "NEES in bounds", "ANIS", "95% bounds (NIS)",
              "NIS in bounds", "diverged", *DIVERGENCE_REASONS, "failed runs", "score not finite"]
    rows = []
    for s in ranked:
        lo, hi = s["anees_bounds"]
        nlo, nhi = s["anis_bounds"]
        rows.append([
            s["estimator"], str(s["runs"]), _fmt(s["anees"]), f"[{_fmt(lo)}, {_fmt(hi)}]",
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
        "and IQRs of every table and counted here."
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


def ranked_summaries(results: Results, scenario: str) -> list[dict[str, Any]]:
    """The summaries of every estimator stored for ``scenario``, ranked (:func:`rank`)."""
    estimators = sorted({r.label for r in results.records if r.scenario == scenario})
    return rank([summarize_pair(results, e, scenario) for e in estimators])


def _scenario_files(results: Results, scenario: str, ranked: Sequence[dict[str, Any]]) -> dict[str, str]:
    quoted = quoted_rows(scenario)
    runs = max(s["runs"] for s in ranked)
    intro = _scenario_intro(results, scenario, runs)
    tables = [_ranking_table(ranked, quoted), _components_table(ranked, quoted), _consistency_table(ranked),
              _settling_table(ranked)]
    title = f"fkn-bench leaderboard: {scenario}"
    markdown = f"# {title}\n\n" + "\n\n".join(intro) + "\n\n" + "\n".join(markdown_table(t) for t in tables)
    page = html_page(title, [p.replace("`", "") for p in intro], tables)
    stem = path_name(scenario)
    return {f"{stem}.md": markdown, f"{stem}.html": page, f"{stem}.csv": _scenario_csv(ranked)}


def _scenario_csv(ranked: Sequence[dict[str, Any]]) -> str:
    records = []
    for i, s in enumerate(ranked, start=1):
        st = s["statistics"]["state_rmse"]
        records.append({
            "rank": i if math.isfinite(_score(s)) else None,
            **{k: s[k] for k in ("estimator", "scenario", "runs", "state_rmse")},
            **{f"state_rmse_{k}": st[k] for k in ("median", "q25", "q75")},
            **{k: s[k] for k in GROUP_RMSE_KEYS.values()},
            **{f"rmse_{n}": s["rmse"][n] for n in STATE_NAMES},
            **{k: s[k] for k in ("settling_time_s", "settled_fraction", "diverged_fraction", "anees")},
            "anees_lower": s["anees_bounds"][0],
            "anees_upper": s["anees_bounds"][1],
            **{k: s[k] for k in ("nees_in_bounds_fraction", "anis", "nis_in_bounds_fraction")},
        })
    frame = pd.DataFrame(records)
    frame["rank"] = frame["rank"].astype("Int64")
    return rows_to_csv(frame, float_format=CSV_FLOAT_FORMAT)


NOTES_FILE = "NOTES.md"
"""Hand-written notes in a results directory, copied into the leaderboard index."""


def _index(results: Results, scenarios: Sequence[str], ranked: dict[str, list[dict[str, Any]]], notes: str | None) -> str:
    positions: dict[str, list[int]] = {}
    scores: dict[tuple[str, str], float] = {}
    for scenario in scenarios:
        for position, summary in enumerate(ranked[scenario]):
            positions.setdefault(summary["estimator"], []).append(position)
            scores[(summary["estimator"], scenario)] = summary["state_rmse"]
    estimators = sorted(positions, key=lambda e: (sum(positions[e]) / len(positions[e]), e))

    def cell(e: str, s: str) -> str:
        text = _fmt(scores.get((e, s)), 4)
        return f"**{text}**" if ranked[s][0]["estimator"] == e and text != _DASH else text

    overview = Table(
        "Overview: 13-state RMSE (mean over seeds, lower is better; best in bold; estimators by mean rank)",
        ["estimator", *scenarios], [[e, *(cell(e, s) for s in scenarios)] for e in estimators],
    )
    links = [
        f"- [{s}]({u}.md) ([HTML]({u}.html), [CSV]({u}.csv)): best {ranked[s][0]['estimator']} "
        f"({_fmt(ranked[s][0]['state_rmse'], 4)})"
        for s, u in ((s, quote(path_name(s))) for s in scenarios)
    ]
    env_lines = [
        f"- fkn-bench {e.get('fkn_bench')}, commit {e.get('git_commit')}, Python {e.get('python')}, "
        f"numpy {e.get('numpy')}, torch {e.get('torch')}, {(e.get('machine') or {}).get('platform')}"
        for e in _environments(results)
    ]
    settings = results.settings()
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
        markdown_table(overview).rstrip("\n"),
        "",
        *(["## Notes", "", f"(From [`results/{NOTES_FILE}`](results/{NOTES_FILE}), written by people; every number "
           "comes with the command that produced it.)", "", notes.strip(), ""] if notes else []),
        "## Scenarios",
        "",
        *links,
        "",
        "## Files",
        "",
        "- `<scenario>.md` / `.html`: ranking, RMSE per component (with the paper's quoted rows on ds1), "
        "consistency and stability, settling times.",
        "- `<scenario>.csv`: the ranking's deterministic columns.",
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


def build_leaderboards(results: Results, notes: str | None = None) -> dict[str, str]:
    """Every leaderboard file as ``{relative path: text}`` (see module docstring); ``notes``
    (Markdown) becomes the index's "Notes" section."""
    if not len(results):
        raise ValueError("no results to build leaderboards from")
    results.check_comparable()
    scenarios = scenario_order(results.scenarios())
    files: dict[str, str] = {}
    ranked = {scenario: ranked_summaries(results, scenario) for scenario in scenarios}
    for scenario in scenarios:
        files.update(_scenario_files(results, scenario, ranked[scenario]))
    files["README.md"] = _index(results, scenarios, ranked, notes)
    files["results.csv"] = rows_to_csv(deterministic_rows(results.rows), float_format=CSV_FLOAT_FORMAT)
    files["provenance.json"] = _provenance(results, scenarios)
    return files


def write_leaderboards(results: Results, out_dir: str | Path, notes: str | None = None, *,
                       force: bool = False) -> list[Path]:
    """Build and write every leaderboard file (atomically) under ``out_dir``, replacing only
    files fkn-bench wrote there unless ``force`` (module docstring); returns the paths. Raises
    :class:`~fkn_bench.harness.manifest.ForeignFileError` (nothing written) for a file in the way."""
    return write_files(out_dir, build_leaderboards(results, notes), force=force, what="leaderboards")
