"""``fkn-bench plot``: PNG figures like the paper's, drawn headless.

For one estimator, scenario and seed (the estimator is run on that seed's episode): the four state
groups with estimate, measurement and truth; every component with its 2-sigma uncertainty band;
the group errors over time with the settling time marked. With ``--results DIR`` (written by
``fkn-bench run --out``) also one bar chart per scenario comparing the estimators stored there.

With ``--ratios`` instead: the inertia-ratio error over time of an estimator that estimates the
ratios (default ``rigid-body-ekf-ratios``), over ``--seeds`` episodes from their first sample, with
the share of seeds below 0.02 at 600 s.

Every PNG names, in its text chunk ``fkn-bench command``, the command that draws it (these
options, ``--out`` left out); a comparison chart also holds the numbers it plots and their SHA-256
(:mod:`fkn_bench.reporting.figures`), as the leaderboards' own charts do.

Examples::

    fkn-bench plot --estimator manual-ekf --scenario ds1 --seed 0 --steps 500 --out figures \\
        --results leaderboards/results
    fkn-bench plot --ratios --scenario tumble-fast --seeds 20 --out figures
"""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path

from fkn_bench.cli import usage_errors
from fkn_bench.cli.options import add_command, add_scenario_file_option, check_minimum, default_leaderboards, load_scenario_files

__all__ = ["add_parser", "run"]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    from fkn_bench.scenarios import SPLITS

    parser = add_command(subparsers, "plot",
                         "draw PNG figures of an estimator's run (and bar charts from stored results)", __doc__)
    parser.add_argument("--estimator", metavar="NAME", help="estimator (default: the best built-in, as fkn-bench run)")
    parser.add_argument("--scenario", default="ds1", metavar="NAME", help="scenario (default: ds1)")
    parser.add_argument("--seed", type=int, default=0, help="episode seed (default: 0)")
    parser.add_argument("--split", default="test", choices=SPLITS, help="episode split (default: test)")
    parser.add_argument("--steps", type=int, metavar="N", help="draw only the first N steps (default: all)")
    parser.add_argument("--cut", type=int, default=100, metavar="STEPS", help="scored window start (default: 100)")
    parser.add_argument("--results", metavar="DIR", nargs="?", const="",
                        help="also draw comparison bar charts from these results (--results alone: leaderboards/results, "
                             "here or in the fkn-bench checkout)")
    parser.add_argument("--out", default="figures", metavar="DIR", help="output directory (default: figures)")
    parser.add_argument("--ratios", action="store_true",
                        help="draw the inertia-ratio error over time instead (estimator default: rigid-body-ekf-ratios)")
    parser.add_argument("--seeds", type=int, default=20, metavar="N", help="--ratios: episodes 0 .. N-1 (default: 20)")
    parser.add_argument("--duration", type=float, default=1000.0, metavar="S",
                        help="--ratios: seconds from the episode start (default: 1000)")
    add_scenario_file_option(parser)
    parser.set_defaults(handler=run)


def _command(args: argparse.Namespace, *, run: bool = True, results: bool = False) -> str:
    """The command that draws a figure of this invocation (module docstring): the options that
    decide what is drawn, ``--out`` left out (the figure is the same wherever it is written)."""
    parts = ["fkn-bench", "plot"]
    if args.ratios:
        parts += ["--ratios", "--scenario", args.scenario, "--seeds", str(args.seeds), "--duration", f"{args.duration:g}"]
        parts += ["--estimator", args.estimator] if args.estimator else []
    elif run:
        parts += ["--estimator", args.estimator] if args.estimator else []
        parts += ["--scenario", args.scenario, "--seed", str(args.seed), "--split", args.split, "--cut", str(args.cut)]
        parts += ["--steps", str(args.steps)] if args.steps is not None else []
    if results:
        parts += ["--results", args.results]
    parts += [f"--scenario-file={path}" for path in getattr(args, "scenario_file", []) or []]
    return shlex.join(parts)


def run(args: argparse.Namespace) -> int:
    from fkn_bench.estimators import UnknownEstimatorError
    from fkn_bench.harness.estimators import SelectionError, select_estimators
    from fkn_bench.harness.grid import path_name
    from fkn_bench.harness.sources import SimulatedSource
    from fkn_bench.harness.store import ResultStore, StoreError
    from fkn_bench.harness.trace import trace
    from fkn_bench.metrics import MetricSettings
    from fkn_bench.reporting.leaderboard import ranked_summaries, scenario_order
    from fkn_bench.reporting.plots import (comparison_chart, comparison_data, errors_figure, save_figure, states_figure,
                                           uncertainty_figure)
    from fkn_bench.reporting.reference import quoted_rows
    from fkn_bench.scenarios import get_scenario

    check_minimum(args, seed=0, steps=2, cut=0, seeds=1)
    load_scenario_files(args)
    scenario = get_scenario(args.scenario)
    if args.ratios:
        return _ratios(args, scenario)
    with usage_errors(UnknownEstimatorError, SelectionError):
        resolved = select_estimators([args.estimator] if args.estimator else None, [scenario]).resolved[0]
    results = None
    if args.results == "":  # --results without a directory
        args.results = str(default_leaderboards() / "results")
    if args.results:
        with usage_errors(StoreError):
            results = ResultStore(args.results).load()

    out = Path(args.out)
    run_trace = trace(resolved, SimulatedSource(scenario, args.split), args.seed)
    stem = f"{path_name(resolved.name)}-{path_name(scenario.name)}-seed{args.seed}"
    command = _command(args)
    written = [
        save_figure(states_figure(run_trace, steps=args.steps), out / f"{stem}-states.png", command=command),
        save_figure(uncertainty_figure(run_trace, steps=args.steps), out / f"{stem}-uncertainty.png", command=command),
        save_figure(errors_figure(run_trace, settings=MetricSettings(cut=args.cut), steps=args.steps),
                    out / f"{stem}-errors.png", command=command),
    ]
    if results is not None:
        for name in scenario_order(results.scenarios()):
            data = comparison_data(name, ranked_summaries(results, name), quoted_rows(name))
            written.append(save_figure(comparison_chart(data), out / f"comparison-{path_name(name)}.png",
                                       command=_command(args, run=False, results=True), data=data))
    for path in written:
        print(path)
    return 0


def _ratios(args: argparse.Namespace, scenario) -> int:  # noqa: ANN001
    from fkn_bench.harness.estimators import resolve_estimator
    from fkn_bench.harness.grid import path_name
    from fkn_bench.harness.ratios import ratio_convergence
    from fkn_bench.reporting.plots import ratio_figure, save_figure

    with usage_errors(ValueError):
        result = ratio_convergence(resolve_estimator(args.estimator or "rigid-body-ekf-ratios", scenario), scenario,
                                   args.seeds, args.duration)
    path = save_figure(ratio_figure([result]), Path(args.out) / f"ratios-{path_name(result.estimator)}-{path_name(scenario.name)}.png",
                       command=_command(args))
    for time in sorted({100.0, 300.0, 600.0, float(args.duration)}):
        print(f"{result.estimator} on {scenario.name}: {result.share_below(0.02, time):.0%} of {args.seeds} seeds "
              f"have inertia-ratio error < 0.02 at {time:g} s (median error {result.median_at(time):.3g})")
    print(path)
    return 0
