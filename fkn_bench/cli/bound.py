"""``fkn-bench bound``: how far from the best possible. The posterior Cramér-Rao bound (PCRB) of a
scenario, the smallest RMSE any estimator can reach given the scenario's stated prior, its
dynamics, its measurement noise and each episode's measurement schedule
(:mod:`fkn_bench.metrics.bound`; Tichavský, Muravchik & Nehorai, IEEE TSP 1998).

With ``--scenario``: the bound of the scenario's first ``--seeds`` episodes of ``--split``, scored
from ``--cut`` steps into the split, per state group and for the 13-state score (mean over the
episodes, its Monte-Carlo standard error, unit), and the stated prior it used; for a free tumble
whose inertia is uncertain also the bound with the inertia known. Outliers and sign flips are not
in it (the bound of the inlier model). ``--plot FILE.png`` draws the bound over time, one panel per
group, against the error curves (root mean square over the episodes at each step) of the
``--estimator`` s, run here on the same episodes.

With ``--results DIR`` (written by ``fkn-bench run --out``): the bounds of the directory's
simulated scenarios (all, or the ``--scenario`` s named), computed where missing or stale and
stored beside the cells (``DIR/bounds/<scenario>.json``, :mod:`fkn_bench.harness.bounds`; the
leaderboards read them), then per scenario the bound row and each stored estimator's 13-state and
group RMSE with its efficiency, bound / RMSE (1.0 is the best possible), the bound averaged over
the seeds the estimator was scored on. ``--force`` recomputes stored bounds.

Examples::

    fkn-bench bound --scenario free-tumble
    fkn-bench bound --scenario spin --seeds 20 --plot spin-bound.png --estimator manual-ekf
    fkn-bench bound --results leaderboards/results --scenario spin
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path
from typing import Any

from fkn_bench.cli import UsageError, usage_errors
from fkn_bench.cli.options import add_command, add_scenario_file_option, check_minimum, default_leaderboards, load_scenario_files

__all__ = ["add_parser", "run"]

_SCENARIO_ONLY = ("seeds", "split", "cut", "inertia", "plot", "estimator")
"""Options of the ``--scenario`` form: with ``--results`` the stored results decide them."""


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    from fkn_bench.scenarios import SPLITS

    parser = add_command(subparsers, "bound",
                         "the posterior Cramér-Rao bound of a scenario, and each stored estimator's efficiency", __doc__)
    parser.add_argument("--scenario", action="append", default=[], metavar="NAME",
                        help="scenario (repeatable; with --results: only these of the stored scenarios)")
    parser.add_argument("--seeds", type=int, metavar="N",
                        help="episodes 0 .. N-1 of the split (default: the scenario's test episodes)")
    parser.add_argument("--split", choices=SPLITS, help="episode split (default: test)")
    parser.add_argument("--cut", type=int, metavar="STEPS", help="first scored step of the split (default: 100)")
    parser.add_argument("--inertia", choices=("scenario", "known"),
                        help="a free tumble's inertia as the scenario states it (default) or known exactly")
    parser.add_argument("--plot", metavar="FILE.png",
                        help="draw the bound over time (one --scenario) against the --estimator s' error curves")
    parser.add_argument("--estimator", action="append", default=[], metavar="NAME",
                        help="--plot: run this estimator on the same episodes and draw its error curve (repeatable)")
    parser.add_argument("--results", metavar="DIR", nargs="?", const="",
                        help="compute and store the bounds of these results (fkn-bench run --out) and print each "
                             "estimator's efficiency (--results alone: leaderboards/results, here or in the checkout)")
    parser.add_argument("--force", action="store_true", help="--results: recompute the stored bounds")
    parser.add_argument("--quiet", action="store_true",
                        help="--results: store the bounds and print only the progress lines, not the tables")
    add_scenario_file_option(parser)
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    check_minimum(args, seeds=1, cut=0)
    load_scenario_files(args)
    if args.results is not None:
        given = [name for name in _SCENARIO_ONLY if getattr(args, name) not in (None, [])]
        if given:
            raise UsageError(f"--{given[0]} goes with --scenario alone: with --results the stored results' seeds, "
                             f"split and cut are used")
        return _stored(args)
    for name, what in (("force", "it recomputes the stored bounds"), ("quiet", "it leaves out the tables")):
        if getattr(args, name):
            raise UsageError(f"--{name} goes with --results ({what})")
    if not args.scenario:
        hint = "--plot draws one scenario's bound: give --scenario NAME" if args.plot else (
            "give --scenario NAME (the bound of its episodes) or --results DIR (the bounds of stored results)")
        raise UsageError(hint)
    if args.plot and len(args.scenario) > 1:
        raise UsageError(f"--plot draws one scenario's bound: give one --scenario (got {len(args.scenario)})")
    if args.estimator and not args.plot:
        raise UsageError("--estimator goes with --plot (the estimators whose error curves are drawn)")
    from fkn_bench.scenarios import get_scenario

    scenarios = [get_scenario(name) for name in args.scenario]  # unknown names: one line before any work
    for scenario in scenarios:
        _check_cut(scenario, args.split or "test", 100 if args.cut is None else args.cut)
    estimators = _estimators(args.estimator, scenarios[0])
    for number, scenario in enumerate(scenarios):
        print(("\n" if number else "") + _scenario_bound(args, scenario, estimators))
    return 0


def _estimators(names: list[str], scenario: Any) -> list[Any]:
    """The ``--estimator`` s built for ``scenario`` (an unknown or unavailable one: one line)."""
    if not names:
        return []
    from fkn_bench.estimators import UnknownEstimatorError
    from fkn_bench.harness.estimators import SelectionError, select_estimators

    with usage_errors(UnknownEstimatorError, SelectionError):
        return select_estimators(names, [scenario]).resolved


def _check_cut(scenario: Any, split: str, cut: int) -> None:
    start, stop = scenario.split_bounds()[split]
    if cut >= stop - start:
        raise UsageError(f"--cut must be below the {split} split's {stop - start} steps of {scenario.name} (got {cut})")


def _bounds(args: argparse.Namespace, scenario: Any) -> tuple[Any, Any]:
    """The bound as asked, and for a free tumble with the inertia estimated also the bound with
    the inertia known (else None)."""
    from fkn_bench.metrics.bound import posterior_bound

    options = {"split": args.split or "test", "cut": 100 if args.cut is None else args.cut}
    bound = posterior_bound(scenario, args.seeds, inertia=args.inertia or "scenario", **options)
    known = posterior_bound(scenario, args.seeds, inertia="known", **options) if bound.inertia == "estimated" else None
    return bound, known


def _scenario_bound(args: argparse.Namespace, scenario: Any, estimators: list[Any]) -> str:
    """The bound of one scenario as text (module docstring); draws ``--plot``."""
    bound, known = _bounds(args, scenario)
    lines = [_heading(bound, scenario), _bound_table(bound, known)]
    lines.append("prior (stated by the scenario):")
    lines += [f"  {name}: {text}" for name, text in scenario.describe_prior().items() if name != "splits"]
    if scenario.outlier_fraction or scenario.sign_flip_probability:
        lines.append("outliers and sign flips are not in the bound: it is the bound of the inlier model")
    if args.plot:
        lines.append(f"figure: {_draw(args, scenario, bound, known, estimators)}")
    return "\n".join(lines)


def _heading(bound: Any, scenario: Any) -> str:
    seeds = bound.seeds
    consecutive = list(seeds) == list(range(seeds[0], seeds[-1] + 1))
    which = f"seeds {seeds[0]}-{seeds[-1]}" if consecutive else "seeds " + ", ".join(map(str, seeds))
    dynamics = "forced rotation" if bound.inertia is None else f"free tumble, inertia {bound.inertia}"
    return (f"posterior Cramér-Rao bound of {scenario.name} ({dynamics}): {len(seeds)} episodes of the {bound.split} "
            f"split ({which}), scored from step {bound.cut} ({bound.cut * scenario.dt:g} s)")


def _bound_table(bound: Any, known: Any) -> str:
    """Rows: the 13-state score and each group; columns: the bound's mean and Monte-Carlo
    standard error (and the known-inertia bound's), unit."""
    from fkn_bench.metrics import GROUP_UNITS
    from fkn_bench.plotting import STATE_RMSE_UNIT
    from fkn_bench.reporting.report import format_number, text_table

    units = {"state": STATE_RMSE_UNIT, **GROUP_UNITS}
    names = {"state": "13-state"}
    summaries = [b.summary() for b in (bound, known) if b is not None]
    label = "bound" if known is None else "bound (inertia estimated)"
    header = ["score", label, "MC s.e."] + (["bound (inertia known)", "MC s.e."] if known is not None else []) + ["unit"]
    rows = []
    for key in summaries[0]:
        cells = [names.get(key, key)]
        for summary in summaries:
            cells += [format_number(summary[key].mean), _standard_error(summary[key].mean, summary[key].standard_error)]
        rows.append(cells + [units[key]])
    return text_table(header, rows, right=range(1, len(header) - 1))


def _standard_error(mean: float, error: float) -> str:
    """Two significant digits of the shown error (:func:`fkn_bench.reporting.bounds.shown_standard_error`)."""
    from fkn_bench.reporting.bounds import shown_standard_error
    from fkn_bench.reporting.report import format_number

    return format_number(shown_standard_error(mean, error), 2)


def _draw(args: argparse.Namespace, scenario: Any, bound: Any, known: Any, estimators: list[Any]) -> Path:
    """Run ``estimators`` on the bound's episodes and save the figure to ``--plot``."""
    from fkn_bench.envs import generate_episodes
    from fkn_bench.reporting.bound_figure import bound_figure, error_curves
    from fkn_bench.reporting.plots import save_figure
    from fkn_bench.runtime import torch_threads

    curves = {}
    if estimators:
        episodes = generate_episodes(scenario, list(bound.seeds), split=bound.split)
        for estimator in estimators:
            print(f"[bound] running {estimator.name} on {len(bound.seeds)} episodes of {scenario.name}", file=sys.stderr)
            with torch_threads():
                estimates = estimator.estimator.estimate(episodes.measurements.copy(), episodes.valid.copy(),
                                                         float(scenario.dt))
            curves[estimator.name] = error_curves(episodes.truth, estimates.means, estimates.initialised)
    figure = bound_figure(bound, curves, known=known)
    return save_figure(figure, args.plot, command=_command(args, scenario.name))


def _command(args: argparse.Namespace, scenario: str) -> str:
    """The command that draws the figure (its file name kept, its directory left out: the figure
    is the same wherever it is written)."""
    parts = ["fkn-bench", "bound", "--scenario", scenario]
    for name in ("seeds", "split", "cut", "inertia"):
        value = getattr(args, name)
        parts += [f"--{name}", str(value)] if value is not None else []
    parts += ["--plot", Path(args.plot).name]
    for name in args.estimator:
        parts += ["--estimator", name]
    parts += [f"--scenario-file={path}" for path in getattr(args, "scenario_file", []) or []]
    return shlex.join(parts)


def _stored(args: argparse.Namespace) -> int:
    """``--results``: store the missing or stale bounds, then print each scenario's table."""
    from fkn_bench.harness.bounds import bound_key, bound_path, store_bounds
    from fkn_bench.harness.records import Results
    from fkn_bench.harness.store import ResultStore, StoreError
    from fkn_bench.io import directory_lock

    if args.results == "":  # --results without a directory
        args.results = str(default_leaderboards() / "results")
    store = ResultStore(args.results)
    try:
        store.check()
        results = store.load()
    except StoreError as exc:
        raise UsageError(f"{exc} (write results with: fkn-bench run --out {args.results})") from None
    stored = results.scenarios()
    missing = [name for name in args.scenario if name not in stored]
    if missing:
        raise UsageError(f"no results for scenario {missing[0]} in {args.results} (it holds: {', '.join(stored)})")
    if args.scenario:
        results = Results([r for r in results.records if r.scenario in args.scenario])
    with usage_errors(ValueError):
        results.check_comparable()
    scenarios = results.scenarios()

    def progress(scenario: str) -> None:
        episodes = len(bound_key(results, scenario)["seeds"])
        print(f"[bound] {scenario}: computing the bound of {episodes} episodes ({bound_path(args.results, scenario)})",
              file=sys.stderr)

    with directory_lock(args.results, "bounds (fkn-bench bound --results)"):
        written = store_bounds(args.results, results, force=args.force, progress=progress)
    for scenario in scenarios:
        if bound_key(results, scenario) is None:
            print(f"[bound] {scenario}: no bound (recorded episodes have no stated prior)", file=sys.stderr)
        elif scenario not in written:
            print(f"[bound] {scenario}: the stored bound is up to date ({bound_path(args.results, scenario)})",
                  file=sys.stderr)
    if args.quiet:
        return 0
    bounds = ResultStore(args.results).load().bounds
    tables = [_efficiency_table(results, scenario, bounds[scenario]) for scenario in scenarios if scenario in bounds]
    print("\n\n".join(tables))
    return 0


def _efficiency_table(results: Any, scenario: str, bound: dict[str, Any]) -> str:
    """The bound row and each stored estimator's RMSE with its efficiency (module docstring)."""
    from fkn_bench.harness.summary import GROUP_RMSE_KEYS
    from fkn_bench.metrics import GROUP_UNITS, GROUPS
    from fkn_bench.reporting.bounds import BOUND_LABEL, efficiencies, format_efficiency
    from fkn_bench.reporting.leaderboard import ranked_and_references
    from fkn_bench.reporting.report import format_number, text_table

    keys = ("state", *GROUPS)
    header = ["estimator", "runs", "13-state", *(f"{g} ({GROUP_UNITS[g]})" for g in GROUPS)]
    summary = bound["summary"]
    rows = [[BOUND_LABEL, str(summary["state"]["episodes"]),
             *(f"{format_number(summary[k]['mean'])} ± {_standard_error(summary[k]['mean'], summary[k]['standard_error'])}"
               for k in keys)]]
    for s in [entry for group in ranked_and_references(results, scenario) for entry in group]:
        eff = efficiencies(s, bound)
        rmse = {"state": s["state_rmse"], **{g: s[GROUP_RMSE_KEYS[g]] for g in GROUPS}}
        label = s["estimator"] + (" (non-causal reference)" if s.get("non_causal") else "")
        rows.append([label, str(s["runs"]), *(f"{format_number(rmse[k])} ({format_efficiency(eff[k], '-')})" for k in keys)])
    inertia = f", inertia {bound['inertia']}" if bound.get("inertia") else ""
    title = (f"{scenario}: {bound['split']} split, scored from step {bound['cut']}{inertia}; "
             f"each cell RMSE (efficiency = bound / RMSE, 1.00 the best possible for a filter; a non-causal "
             f"smoother reads later measurements and may pass it)")
    return title + "\n" + text_table(header, rows)
