"""``fkn-bench leaderboard``: build the leaderboards from stored results.

Reads the per-cell results that ``fkn-bench run --out DIR`` wrote and writes, under ``--out``, one
Markdown table, HTML page and CSV per scenario, an index (README.md), the per-seed CSV of record
(results.csv) and provenance.json, and under ``--out``/figures the comparison chart of each
headline scenario with results (spin, free-tumble, ds1: ``comparison-<scenario>.png``). The text
files are a pure function of the results: rebuilding from the same results gives byte-identical
files; each chart holds, in its PNG text chunks, the command that draws it and the numbers it
plots with their SHA-256, so it can be checked against the tables without comparing pixels.

Each mean comes with its 95% Student-t confidence interval over the test episodes (seeds); an
estimator that a two-sided Wilcoxon signed-rank test on the per-seed scores cannot separate from
the one ranked above (p >= 0.05) shares its rank. The index leads with the prior families, then
the paper's fixed-truth scenarios, each section ranked on its own
(:mod:`fkn_bench.reporting.leaderboard`).

``--out`` (default: the directory holding ``--results``) keeps a list of the files fkn-bench
wrote there with their SHA-256 (``.fkn-bench-files.json``; ``figures/`` has its own list): a file
is replaced only when fkn-bench wrote it and nobody edited it since, or when it already holds the
new text; any other file in the way (your own README.md, results.csv or
figures/comparison-ds1.png) is refused in one line naming it, and nothing is written, unless
``--force``. Results that mix, for one scenario, another split, cut or scenario
configuration are refused in one line: build those from one results directory each.

``--novelty SCENARIO`` prints instead, from the same results, each estimator's mean 13-state RMSE
on the test episodes of SCENARIO whose spin axis is near / far (45 deg) from every trajectory its
family trained on (:mod:`fkn_bench.harness.novelty`): a filter that estimates scores alike on both.

Regenerate the committed leaderboards from scratch (cells already stored are reused; add --rerun
to the first command to recompute them)::

    fkn-bench run --all --out leaderboards/results --no-progress && fkn-bench leaderboard
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fkn_bench.cli import UsageError, usage_errors
from fkn_bench.cli.options import add_command, default_leaderboards

__all__ = ["add_parser", "run"]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(subparsers, "leaderboard", "build leaderboards (Markdown, HTML, CSV, comparison charts) from stored results",
                         __doc__)
    parser.add_argument("--results", metavar="DIR",
                        help="results directory written by fkn-bench run --out (default: leaderboards/results, here "
                             "or in the fkn-bench checkout)")
    parser.add_argument("--out", metavar="DIR",
                        help="where to write the leaderboards (default: the directory holding --results); files "
                             "fkn-bench did not write there are never replaced without --force")
    parser.add_argument("--force", action="store_true",
                        help="replace files in --out that fkn-bench did not write (or that were edited since)")
    parser.add_argument("--cross", action="store_true",
                        help="instead: run every learned or tuned estimator with every family's committed parameters "
                             "on every named scenario and write the cross-scenario table (cross-scenario.md/.csv)")
    parser.add_argument("--shift", action="store_true",
                        help="instead: score each prior family's learned and tuned estimators, and manual-ekf, on "
                             "shifted priors and write the shift table (shift.md/.csv)")
    parser.add_argument("--novelty", metavar="SCENARIO",
                        help="instead: print, from the stored results, each estimator's mean 13-state RMSE on the test "
                             "episodes of SCENARIO whose spin axis is near / far from every trajectory its family's "
                             "artefacts trained on (fkn_bench.harness.novelty); writes nothing")
    parser.add_argument("--seeds", type=int, default=None, metavar="N",
                        help="--cross, --shift: test episodes 0 .. N-1 (default: 20 for --cross, 50 for --shift)")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    if args.results is None:
        args.results = str(default_leaderboards() / "results")
    if args.out is None:
        args.out = str(Path(args.results).parent)
    if sum(map(bool, (args.cross, args.shift, args.novelty))) > 1:
        raise UsageError("--cross, --shift and --novelty make different tables: give one")
    if args.novelty:
        return _novelty(args)
    if args.cross:
        return _cross(args)
    if args.shift:
        return _shift(args)
    if args.seeds is not None:
        raise UsageError("--seeds goes with --cross or --shift (the leaderboards take the stored results' seeds)")
    from fkn_bench.harness.store import ResultStore, StoreError
    from fkn_bench.reporting.leaderboard import NOTES_FILE, write_leaderboards

    try:
        results = ResultStore(args.results).load()
        notes = Path(args.results) / NOTES_FILE
        paths = write_leaderboards(results, args.out, notes.read_text(encoding="utf-8") if notes.is_file() else None,
                                   force=args.force)
    except StoreError as exc:
        raise UsageError(f"{exc} (write results with: fkn-bench run --all --out {args.results})") from None
    except ValueError as exc:  # results that cannot be combined (mixed settings); a file in the way
        raise UsageError(str(exc)) from None
    print(f"fkn-bench leaderboard: wrote {len(paths)} files from {len(results)} cells to {args.out}", file=sys.stderr)
    for path in paths:
        print(path)
    return 0


def _novelty(args: argparse.Namespace) -> int:
    import math

    from fkn_bench.harness.novelty import NEAR_DEGREES, novelty_table
    from fkn_bench.harness.store import ResultStore, StoreError

    if args.seeds is not None:
        raise UsageError("--seeds goes with --cross or --shift (--novelty reads the stored results' seeds)")
    try:
        rows = ResultStore(args.results).load().rows
    except StoreError as exc:
        raise UsageError(f"{exc} (write results with: fkn-bench run --all --out {args.results})") from None
    with usage_errors(ValueError, KeyError):
        table, degrees = novelty_table(rows, args.novelty)
    far = int((degrees > NEAR_DEGREES).sum())
    print(f"{args.novelty}: angle (deg) from each test episode's angular momentum to the nearest training "
          f"trajectory's, seeds 0..{len(degrees) - 1}: {' '.join(f'{d:.0f}' for d in degrees)}")
    print(f"near: <= {NEAR_DEGREES:g} deg ({len(degrees) - far} episodes); far: > {NEAR_DEGREES:g} deg ({far} episodes)\n")
    print("| estimator | near RMSE | far RMSE | far / near | diverged near | diverged far |")
    print("|:---|---:|---:|---:|---:|---:|")
    for row in table.itertuples(index=False):
        cells = [f"{value:.4g}" if not math.isnan(value) else "–" for value in (row[1], row[2], row[3])]
        print(f"| {row[0]} | {' | '.join(cells)} | {row[4]} | {row[5]} |")
    return 0


CROSS_ESTIMATORS = ("flexkalmannet", "flexkalmannet-rigid-body", "nll-tuned-ekf", "direct-tuned-ekf")
CROSS_FAMILIES = ("ds1", "ds2", "tumble", "default", "ds1-noise-step")
"""The paper's families and the default mixture: the prior families' own shifts are the shift table's."""


def _cross(args: argparse.Namespace) -> int:
    from fkn_bench.harness.cross import cross_scores
    from fkn_bench.reporting.cross import cross_table
    from fkn_bench.reporting.manifest import check_files, write_files
    from fkn_bench.reporting.tables import markdown_table
    from fkn_bench.scenarios import get_scenario, scenario_names

    args.seeds = 20 if args.seeds is None else args.seeds
    if args.seeds < 1:
        raise UsageError(f"--seeds must be a positive integer (got {args.seeds})")
    names = ["cross-scenario.md", "cross-scenario.csv"]
    with usage_errors(ValueError):
        check_files(args.out, names, force=args.force)  # before minutes of work
    scenarios = [name for name in scenario_names() if "prior" not in get_scenario(name).tags]  # the paper's scenarios
    table = cross_table(cross_scores(CROSS_ESTIMATORS, CROSS_FAMILIES, scenarios, args.seeds), scenarios)
    header = f"# Cross-scenario table ({args.seeds} seeds)\n\nRegenerate: `fkn-bench leaderboard --cross --seeds {args.seeds}`\n\n"
    with usage_errors(ValueError):
        paths = write_files(args.out, dict(zip(names, (header + markdown_table(table), table.to_csv()))),
                            force=args.force, what="the cross-scenario table")
    for path in paths:
        print(path)
    return 0


def _shift(args: argparse.Namespace) -> int:
    from fkn_bench.harness.shift import SHIFTS, shift_scores
    from fkn_bench.reporting.manifest import check_files, write_files
    from fkn_bench.reporting.shift import shift_documents

    args.seeds = 50 if args.seeds is None else args.seeds
    if args.seeds < 2:
        raise UsageError(f"--seeds must be an integer >= 2 (got {args.seeds})")
    names = ["shift.md", "shift.csv"]
    with usage_errors(ValueError):
        check_files(args.out, names, force=args.force)  # before minutes of work
    scores = shift_scores(list(SHIFTS), args.seeds, progress=lambda what: print(f"[shift] {what}", file=sys.stderr))
    with usage_errors(ValueError):
        paths = write_files(args.out, dict(zip(names, shift_documents(scores, args.seeds))), force=args.force,
                            what="the shift table")
    for path in paths:
        print(path)
    return 0
