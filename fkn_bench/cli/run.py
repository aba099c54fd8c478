"""``fkn-bench run``: run estimators on scenarios over seeds and score them.

Runs the grid estimator x scenario x seed (cells of 10 consecutive seeds), prints a table (or,
with ``--json``, one JSON document) with one line per estimator and scenario, and with ``--out``
writes every cell's results there as it completes, so an interrupted run resumes where it
stopped (a stored cell whose data does not match its recorded SHA-256 is recomputed, with a line
on stderr). ``--out`` writes only into a directory fkn-bench created (its ``.fkn-bench-results``
marker or an earlier run's ``results.json``), a new one or an empty one; any other directory is
refused unless ``--force``. A cell is filed under its estimator, scenario and variant (split,
``--cut``, ``--estimator-option`` values and the scenario's configuration hash:
``cells/<estimator>/<scenario>/<variant>/seeds-A-B.*``), so runs that differ there share an
``--out`` without replacing each other's cells; an estimator run with options is shown as
``manual-ekf (gate=0.5)``. One run at a time writes to an ``--out`` (a second is refused, exit 2);
a killed run leaves nothing that the next run trusts and resumes to the same results. Results are
identical for the same seeds whatever the backend or worker count.

With ``--all`` (or ``--training-seeds``) every other training seed of an estimator whose committed
parameters a seed study chose (``fkn-bench train --seeds``, :mod:`fkn_bench.training.seeds`) runs
too, as ``flexkalmannet (training_seed=1)``: the leaderboards fold those rows into the estimator's
training-seed spread instead of ranking them.

Examples::

    fkn-bench run                                   # the best built-in estimator on spin (a prior family), 20 test episodes
    fkn-bench run --estimator manual-ekf --scenario ds1 --scenario ds2 --seeds 50 --json
    fkn-bench run --all --out leaderboards/results            # every estimator x scenario, each its test episodes
    fkn-bench run --all --backend dask --workers 4              # on a local Dask cluster
    fkn-bench run --recording run.mcap --estimator manual-ekf    # replay a recording (MCAP)
    fkn-bench run --recording run.mcap --estimate-topic /loc/pose --estimate myfilter.tum --estimator manual-ekf

With ``--recording`` the whole recording is one episode (truth from ``--truth-topic``, by default
the truth of an fkn-bench recording or Astrobee's ``<robot>/loc/truth/pose``); measurements come
from ``--measurement-topic`` as recorded, or are synthesised from the truth with the noise model
of the recording's scenario, one noise draw per seed (``--seeds``; default 1 with recorded
measurements, which do not depend on the seed).

Other programs' estimates of the recording are scored beside the estimators, with the same
metrics: ``--estimate-topic TOPIC`` (a pose topic of the recording: ``PoseStamped``,
``PoseWithCovarianceStamped`` or ``Odometry``) and ``--estimate FILE`` (TUM ``.tum``/``.txt`` or
``.csv``, :mod:`fkn_bench.recordings.trajectories`), each a row ``external:<topic>`` or
``external:<file name>`` (no cost columns: fkn-bench did not run them). They are interpolated onto
the truth's grid on the truth's clock (slerp for the attitude) within ``--association-tolerance``
seconds of their stamps (default: twice their median interval); ``--align se3`` first aligns them
rigidly to the truth (Umeyama) and prints the transform (:mod:`fkn_bench.envs.association`).
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from fkn_bench.cli import Interrupted, UsageError, usage_errors
from fkn_bench.cli.options import (add_command, add_scenario_file_option, check_minimum, load_scenario_files,
                                   parse_key_values)

__all__ = ["add_parser", "run", "DEFAULT_SCENARIO", "DEFAULT_SEEDS"]

DEFAULT_SCENARIO = "spin"
DEFAULT_SEEDS = 20
"""Default seed count: with 20 runs the per-step 95% ANEES interval for the 12-dim error is
[10.0, 14.2] (half-width ~17%), narrow enough for the chi-square test to separate a consistent
filter from an over- or under-confident one."""


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    from fkn_bench.harness.backends import BACKENDS
    from fkn_bench.scenarios import SPLITS

    parser = add_command(subparsers, "run", "run estimators on scenarios and score them", __doc__)
    parser.add_argument("--estimator", action="append", metavar="NAME",
                        help="estimator to run (repeatable; default: flexkalmannet when available, else manual-ekf)")
    parser.add_argument("--scenario", action="append", metavar="NAME",
                        help=f"scenario to run on (repeatable; default: {DEFAULT_SCENARIO})")
    parser.add_argument("--all", action="store_true",
                        help="every available estimator on every named scenario (--estimator/--scenario narrow it)")
    parser.add_argument("--seeds", type=int, default=None, metavar="N",
                        help="run seeds (test episodes) 0 .. N-1 (default: each scenario's own test_episodes: 50 on "
                             f"the prior families' headline scenarios, 10 on their stress variants, {DEFAULT_SEEDS} on "
                             f"the paper's; {DEFAULT_SEEDS} on a dataset or a recording)")
    parser.add_argument("--split", default="test", choices=SPLITS, help="episode split to score (default: test)")
    parser.add_argument("--cut", type=int, default=100, metavar="STEPS",
                        help="first scored step of each run: the paper's loss cut (default: 100)")
    parser.add_argument("--json", action="store_true", help="print exactly one JSON document on stdout")
    parser.add_argument("--out", metavar="DIR", help="write per-cell results here (and resume from them)")
    parser.add_argument("--rerun", action="store_true", help="recompute cells already finished in --out")
    parser.add_argument("--force", action="store_true",
                        help="write into an --out directory that fkn-bench did not create (its cells/, results.csv "
                             "and results.json are overwritten)")
    parser.add_argument("--backend", default="local", choices=BACKENDS, help="where cells run (default: local)")
    parser.add_argument("--workers", type=int, default=1, metavar="N",
                        help="worker processes (local: a process pool when > 1; dask: LocalCluster size)")
    parser.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler address (default: start a LocalCluster)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    parser.add_argument("--training-seeds", action=argparse.BooleanOptionalAction, default=None,
                        help="also run every other training seed of an estimator whose committed parameters a seed "
                             "study chose (fkn-bench train --seeds), for the leaderboards' training-seed spread "
                             "(default: with --all)")
    parser.add_argument("--estimator-option", action="append", default=[], metavar="KEY=VALUE",
                        help="option for the estimators' factories, e.g. parameters=runs/fkn/parameters.json "
                             "(repeatable)")
    parser.add_argument("--dataset", metavar="DIR",
                        help="run on this Minari dataset (fkn-bench dataset; instead of --scenario): its seeds, "
                             "or seeds 0 .. N-1 with --seeds N")
    replay = parser.add_argument_group("recordings (instead of --scenario)")
    replay.add_argument("--recording", metavar="FILE.mcap", help="run on this MCAP recording")
    replay.add_argument("--truth-topic", metavar="TOPIC", help="pose topic of the ground truth")
    replay.add_argument("--measurement-topic", metavar="TOPIC", help="pose topic of the measurements (default: synthesise)")
    replay.add_argument("--repair", action="store_true", help="repair broken recordings (sort, deduplicate, renormalise)")
    replay.add_argument("--dt", metavar="SECONDS|native", help="replay time step (default: the scenario's)")
    replay.add_argument("--time-source", choices=("auto", "header", "log"), default="auto",
                        help="message times: header stamps, MCAP log times, or auto (header unless all zero)")
    replay.add_argument("--quaternion-tolerance", type=float, default=1e-6, metavar="TOL",
                        help="largest accepted |norm - 1| of a recorded quaternion (default: 1e-6)")
    external = parser.add_argument_group("external estimates (with --recording)")
    external.add_argument("--estimate-topic", action="append", default=[], metavar="TOPIC",
                          help="score another program's estimate on this pose topic of the recording (PoseStamped, "
                               "PoseWithCovarianceStamped, Odometry) as row external:TOPIC (repeatable)")
    external.add_argument("--estimate", action="append", default=[], metavar="FILE.tum|FILE.csv",
                          help="score the estimate in this TUM or CSV file (times on the recording's clock) as row "
                               "external:FILE-NAME (repeatable)")
    external.add_argument("--align", choices=("none", "se3"), default="none",
                          help="align external estimates rigidly to the truth first (se3: Umeyama, no scale; "
                               "default: none)")
    external.add_argument("--association-tolerance", type=float, metavar="SECONDS",
                          help="largest gap between a truth step and the estimate stamps around it that is "
                               "interpolated (default: twice the estimate's median interval)")
    add_scenario_file_option(parser)
    parser.set_defaults(handler=run)


def _check_arguments(args: argparse.Namespace) -> None:
    check_minimum(args, seeds=1, workers=1, cut=0)
    if args.scheduler is not None and args.backend != "dask":
        raise UsageError("--scheduler needs --backend dask")
    if args.rerun and not args.out:
        raise UsageError("--rerun needs --out (without it nothing is reused)")
    if args.force and not args.out:
        raise UsageError("--force needs --out (without it nothing is written)")
    external = args.estimate_topic or args.estimate
    if (external or args.align != "none" or args.association_tolerance is not None) and not args.recording:
        raise UsageError("--estimate-topic, --estimate, --align and --association-tolerance need --recording")
    if (args.align != "none" or args.association_tolerance is not None) and not external:
        raise UsageError("--align and --association-tolerance need --estimate-topic or --estimate")
    if args.association_tolerance is not None and not args.association_tolerance > 0:
        raise UsageError(f"--association-tolerance must be a positive number of seconds (got {args.association_tolerance})")


@contextmanager
def _store_errors() -> Iterator[None]:
    """:class:`~fkn_bench.harness.StoreError` s of ``--out`` as one-line usage errors naming it
    (a foreign directory with the hint to use ``--force``)."""
    from fkn_bench.harness import ForeignDirectoryError, StoreError

    try:
        yield
    except ForeignDirectoryError as exc:
        raise UsageError(f"--out: {exc}; choose another directory, or pass --force to write cells/, results.csv "
                         f"and results.json there anyway") from None
    except StoreError as exc:
        raise UsageError(f"--out: {exc}") from None


def _store(args: argparse.Namespace) -> Any:
    """The result store of ``--out``, checked to be fkn-bench's before anything runs
    (:meth:`~fkn_bench.harness.ResultStore.check`; it is marked, locked and written by
    :func:`~fkn_bench.harness.run_grid`); a directory fkn-bench did not write is refused unless
    ``--force``."""
    from fkn_bench.harness import ResultStore

    store = ResultStore(args.out)
    with _store_errors():
        store.check(force=args.force)
    return store


def _estimators(args: argparse.Namespace, scenarios: list[Any]) -> list[Any]:
    """The resolved (estimator, scenario) pairs to run (:func:`fkn_bench.harness.select_estimators`:
    its notes go to stderr, its refusals are usage errors)."""
    from fkn_bench.estimators import UnknownEstimatorError
    from fkn_bench.harness import SelectionError, select_estimators

    options = parse_key_values(args.estimator_option, "--estimator-option")
    if options and not args.estimator:
        raise UsageError("--estimator-option needs --estimator NAME")
    with usage_errors(UnknownEstimatorError, SelectionError):
        seeds = args.all if args.training_seeds is None else args.training_seeds
        selection = select_estimators(args.estimator, scenarios, every=args.all, options=options,
                                      training_seeds=seeds and not options)
    for note in selection.notes:
        print(f"fkn-bench run: {note}", file=sys.stderr)
    return selection.resolved


def _scenarios(args: argparse.Namespace) -> list[Any]:
    from fkn_bench.scenarios import get_scenario, scenario_names

    names = args.scenario or (scenario_names() if args.all else [DEFAULT_SCENARIO])
    scenarios = [get_scenario(name) for name in dict.fromkeys(names)]  # unknown: exit 2 with the list
    for scenario in scenarios:
        start, stop = scenario.split_bounds()[args.split]
        if args.cut >= stop - start:
            raise UsageError(f"--cut {args.cut} leaves nothing to score in the {args.split} split of "
                             f"{scenario.name} ({stop - start} steps)")
    return scenarios


def _dataset_source(args: argparse.Namespace) -> Any:
    """The source of ``--dataset`` (its problems are usage errors naming the directory)."""
    from fkn_bench.exporters import DatasetError, DatasetSource

    if args.scenario or args.all or args.recording:
        raise UsageError("--dataset replaces --scenario, --all and --recording")
    source = DatasetSource(str(args.dataset), args.split)
    with usage_errors(DatasetError, OSError):
        stored = source.stored()
        source.load(source.seeds if args.seeds == DEFAULT_SEEDS else range(args.seeds))  # the split and seeds exist
    start, stop = source.scenario.split_bounds()[args.split] if stored.split == "full" else (0, stored.episodes.n_steps)
    if args.cut >= stop - start:
        raise UsageError(f"--cut {args.cut} leaves nothing to score in the {args.split} split of the dataset "
                         f"({stop - start} steps)")
    print(f"dataset {args.dataset}: {len(stored.episodes.seeds)} episode(s) of {source.scenario.name} "
          f"({stored.split}), scoring the {args.split} split", file=sys.stderr)
    return source


def _recording_source(args: argparse.Namespace) -> Any:
    """The recording source of ``--recording`` (errors naming the file are usage errors)."""
    from fkn_bench.harness import RecordingSource
    from fkn_bench.recordings import RecordingError

    if args.scenario or args.all:
        raise UsageError("--recording replaces --scenario and --all")
    options: dict[str, Any] = {"repair": bool(args.repair)}
    if args.time_source != "auto":
        options["time_source"] = args.time_source
    if args.quaternion_tolerance != 1e-6:
        if not args.quaternion_tolerance > 0:
            raise UsageError(f"--quaternion-tolerance must be a positive number (got {args.quaternion_tolerance})")
        options["quaternion_tolerance"] = args.quaternion_tolerance
    for topic in ("truth_topic", "measurement_topic"):
        if getattr(args, topic):
            options[topic] = getattr(args, topic)
    if args.dt is not None:
        try:
            options["dt"] = args.dt if args.dt == "native" else float(args.dt)
        except ValueError:
            raise UsageError(f"--dt must be a number of seconds or 'native' (got {args.dt!r})") from None
    source = RecordingSource(str(args.recording), tuple(sorted(options.items())))
    with usage_errors(RecordingError, OSError):
        print(source.trajectory().report.summary(), file=sys.stderr)
    return source


def _external_estimators(args: argparse.Namespace, recording: Any) -> list[Any]:
    """The resolved external estimates of ``--estimate-topic`` and ``--estimate`` (their problems
    are usage errors naming the topic or file); each one's association summary goes to stderr."""
    from fkn_bench.harness.sources import external_estimators
    from fkn_bench.recordings import RecordingError

    if not (args.estimate_topic or args.estimate):
        return []
    with usage_errors(RecordingError, OSError, ValueError):
        resolved = external_estimators(recording, args.estimate_topic, args.estimate,
                                       tolerance_s=args.association_tolerance,
                                       align=None if args.align == "none" else args.align)
    for pair in resolved:
        print(pair.estimator.associated.summary(), file=sys.stderr)
    return resolved


def _parameter_sources(resolved: Any) -> list[str]:
    """One line per learned or tuned estimator: the parameter file (or checkpoint) it runs with,
    and the scenario those parameters were trained on (several scenarios sharing a file: one line)."""
    used: dict[tuple[str, str], list[str]] = {}
    for pair in resolved:
        metadata = getattr(pair.estimator, "metadata", None) or {}
        source = metadata.get("artifact") or metadata.get("checkpoint") or getattr(pair.estimator, "checkpoint", None)
        if source:
            trained = metadata.get("scenario")
            trained = trained.get("name") if isinstance(trained, dict) else trained
            key = (pair.name, f"{source}" + (f" (trained on {trained})" if trained else ""))
            used.setdefault(key, []).append(pair.scenario)
    return [f"{name} on {', '.join(scenarios)}: parameters {source}" for (name, source), scenarios in used.items()]


def _default_noise_notes(results: Any) -> list[str]:
    """One line per estimator and scenario whose measured steps took the default R for want of a
    usable stated covariance (``measurement_noise=message``; the cells' notes count them)."""
    counts: dict[tuple[str, str], int] = {}
    for record in results.records:
        if "measurement_noise_defaults" in record.notes:
            key = (record.label, record.scenario)
            counts[key] = counts.get(key, 0) + int(record.notes["measurement_noise_defaults"])
    return [f"fkn-bench run: {label} on {scenario}: {count} measured step(s) stated no usable covariance "
            "(missing, not finite, not symmetric or not positive definite) and took the estimator's own R"
            for (label, scenario), count in counts.items() if count]


def run(args: argparse.Namespace) -> int:
    from fkn_bench.harness import (
        MetricSettings,
        SimulatedSource,
        build_grid,
        make_backend,
        run_grid,
        summarize_results,
    )
    from fkn_bench.harness.grid import estimator_label
    from fkn_bench.reporting import summary_text
    from fkn_bench.io import to_jsonable

    per_scenario = args.seeds is None  # simulated scenarios: each its own test_episodes
    if per_scenario:
        args.seeds = DEFAULT_SEEDS
    _check_arguments(args)
    load_scenario_files(args)
    seeds: Any = None  # range(--seeds), or a dataset's own seeds
    external: list[Any] = []  # resolved external estimates (--estimate-topic, --estimate)
    if args.dataset:
        dataset = _dataset_source(args)
        seeds = dataset.seeds if args.seeds == DEFAULT_SEEDS else None
        scenarios = [dataset.scenario]
        sources: list[Any] = [dataset]
    elif args.recording:
        recording = _recording_source(args)
        if args.measurement_topic and args.seeds == DEFAULT_SEEDS:
            args.seeds = 1  # recorded measurements: every seed would score the same data
        if args.cut >= recording.scenario.n_steps:
            raise UsageError(f"--cut {args.cut} leaves nothing to score in the recording ({recording.scenario.n_steps} steps)")
        scenarios = [recording.scenario]
        sources = [recording]
        external = _external_estimators(args, recording)
    else:
        scenarios = _scenarios(args)
        sources = [SimulatedSource(scenario, args.split) for scenario in scenarios]
    resolved = _estimators(args, scenarios) + external
    for line in _parameter_sources(resolved):
        print(line, file=sys.stderr)
    settings = MetricSettings(cut=args.cut)
    if per_scenario and not (args.dataset or args.recording):  # each scenario its own number of test episodes
        counts = {source.scenario.name: source.scenario.test_episodes for source in sources}
        cells = [cell for n in dict.fromkeys(counts.values())
                 for cell in build_grid([r for r in resolved if counts[r.scenario] == n],
                                        [s for s in sources if counts[s.scenario.name] == n], range(n), settings=settings)]
        args.seeds = next(iter(counts.values())) if len(set(counts.values())) == 1 else counts
    else:
        cells = build_grid(resolved, sources, range(args.seeds) if seeds is None else seeds, settings=settings)
    store = _store(args) if args.out else None
    backend = make_backend(args.backend, workers=args.workers, scheduler=args.scheduler)
    try:
        with _store_errors():
            outcome = run_grid(cells, store=store, backend=backend, progress=not args.no_progress, rerun=args.rerun,
                               force=args.force)
    except KeyboardInterrupt:
        if store is None:
            raise
        raise Interrupted(f"the finished cells are saved in {args.out}: run the same command again to resume") from None
    order = [(estimator_label(r.name, r.options), r.scenario) for r in resolved]
    summaries = summarize_results(outcome.results, order)
    for line in _default_noise_notes(outcome.results):
        print(line, file=sys.stderr)
    if args.json:
        document = {
            "fkn_bench_command": "run",
            "split": args.split,
            "cut": args.cut,
            "seeds": args.seeds if seeds is None else len(seeds),
            "backend": args.backend,
            "out": args.out,
            "cells": {"total": len(cells), "computed": outcome.computed, "reused": outcome.reused,
                      "failed": outcome.failed},
            "results": summaries,
        }
        if external:
            document["external"] = {pair.name: pair.estimator.report() for pair in external}
        print(json.dumps(to_jsonable(document), indent=2))
    else:
        # on a terminal the table fits its width (two stacked tables when needed); piped or
        # redirected output keeps the one wide table, for scripts
        width = shutil.get_terminal_size().columns if sys.stdout.isatty() else None
        print(summary_text(summaries, width=width))
    if args.out:
        mismatched = f", {len(outcome.mismatched)} after a checksum mismatch" if outcome.mismatched else ""
        print(f"fkn-bench run: {len(cells)} cells ({outcome.computed} computed{mismatched}, {outcome.reused} reused, "
              f"{outcome.failed} failed) in {args.out}", file=sys.stderr)
    return 1 if cells and outcome.failed == len(cells) else 0
