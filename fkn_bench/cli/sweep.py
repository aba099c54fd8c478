"""``fkn-bench sweep``: hyperparameter search for FlexKalmanNet (or any trainable estimator) on
optuna, following the paper's method: a random search to narrow the space, then a grid search
over the reduced space (``--sampler random-grid``, the default); ``tpe``, ``random`` and ``grid``
run one stage.

The search space is a TOML file (``--space FILE``, or the name of a packaged space: ``paper``,
``quick``; see ``fkn_bench/sweep/space.py`` for the format). Trials report their validation RMSE
after every epoch and are pruned by the space's pruner (median by default). The study lives in a
journal file (``--storage``, default ``OUT/study.journal``) or any RDB URL
(``sqlite:///sweep.db``, ``postgresql://...``), so that several processes or machines share it:
``--workers N`` runs N processes here; run the same command elsewhere with the same
``--storage`` and ``--study-name`` to add machines. A sweep killed or interrupted goes on where it
stopped when the same command runs again, to the trials an uninterrupted sweep gives (its
interrupted trials are retried, not counted against ``--trials``); two sweeps into one ``--out``
at once are refused.

Outputs in ``--out`` (default ``runs/sweep-<study name>``): ``best.toml`` (for ``fkn-bench train
--config`` and ``fkn-bench reproduce --config``), ``trials.csv``, ``parallel_coordinates.png``
and ``sweep.json``.

Examples::

    fkn-bench sweep --space quick --workers 2
    fkn-bench sweep --space paper --workers 2 --storage runs/paper.journal --study-name paper
"""

from __future__ import annotations

import argparse
import sys
import typing
from pathlib import Path
from typing import Any

from fkn_bench.cli import Interrupted, UsageError, usage_errors
from fkn_bench.cli.options import add_command, add_scenario_file_option, check_minimum, load_scenario_files, output_directory

__all__ = ["add_parser", "run"]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    from fkn_bench.sweep.space import SAMPLERS

    parser = add_command(subparsers, "sweep", "hyperparameter search (random then grid, or TPE) on optuna",
                         __doc__)
    parser.add_argument("--space", required=True, metavar="TOML",
                        help="search-space file, or a packaged space name (paper, quick, seeds, kalmannet-seeds)")
    parser.add_argument("--estimator", help="trainable estimator (default: the space's, else flexkalmannet)")
    parser.add_argument("--scenario", help="training scenario (default: the space's, else ds1)")
    parser.add_argument("--trials", type=int, metavar="N",
                        help="trials of the random (or only) stage; with --sampler grid, at most this many grid "
                             "points (default: the space's, else 20)")
    parser.add_argument("--grid-trials", type=int, metavar="N",
                        help="random-grid: most points of the reduced grid (default: the space's, else --trials)")
    parser.add_argument("--top-k", type=int, metavar="K",
                        help="random-grid: best random trials spanning the reduced grid (default: the space's, else 3)")
    parser.add_argument("--sampler", choices=SAMPLERS, help="search method (default: the space's, else random-grid)")
    parser.add_argument("--workers", type=int, default=1, metavar="N", help="parallel worker processes here (default: 1)")
    parser.add_argument("--storage", metavar="PATH|URL",
                        help="journal file or RDB URL shared by the workers (default: OUT/study.journal)")
    parser.add_argument("--study-name", metavar="NAME", help="study name (default: <estimator>-<scenario>)")
    parser.add_argument("--seed", type=int, help="sampler seed (default: the space's, else 0)")
    parser.add_argument("--out", type=Path, metavar="DIR", help="output directory (default: runs/sweep-<study name>)")
    parser.add_argument("--no-progress", action="store_true", help="no per-trial messages")
    parser.add_argument("--write-artifact", action="store_true",
                        help="a non-trainable estimator (the adaptive baselines): install the best options as its "
                             "committed settings for the scenario's model family")
    add_scenario_file_option(parser)
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from fkn_bench.estimators import UnknownEstimatorError
    from fkn_bench.scenarios import get_scenario
    from fkn_bench.sweep import SearchSpace, SpaceError, SweepError, SweepSettings, load_space, resolve_space, run_sweep
    from fkn_bench.sweep import trial_config
    from fkn_bench.runtime import resolve_device
    from fkn_bench.sweep.objective import is_trainable
    from fkn_bench.sweep.study import storage_label
    from fkn_bench.training import trainable

    check_minimum(args, trials=1, grid_trials=1, top_k=1, workers=1, seed=0)
    load_scenario_files(args)
    with usage_errors(SpaceError):
        space: SearchSpace = load_space(resolve_space(args.space))

    def option(name: str, fallback: object = None) -> Any:
        """The command line's value of option ``name``, else the space's ``[sweep]`` default."""
        value = getattr(args, name)
        return value if value is not None else space.defaults.get(name, fallback)

    estimator = option("estimator", "flexkalmannet")
    scenario = get_scenario(option("scenario", "ds1"))
    sampler = option("sampler", "random-grid")
    with usage_errors(UnknownEstimatorError, SpaceError, ValueError, TypeError):
        if is_trainable(estimator):
            defaults = trainable(estimator).config({})
            fields = {"device": "cpu", **defaults.to_dict()}  # (to_dict leaves the CPU out)
            space.check_fields(fields, f"{estimator} training config")
            space.check_kinds(typing.get_type_hints(type(defaults)))
            try:
                fixed = trial_config(estimator, space, {})  # the fixed values on their own must be valid
            except (ValueError, TypeError) as exc:
                raise UsageError(f"{space.source}: [fixed]: {exc}") from None
            resolve_device(fixed.train_config().device)  # (a GPU the space names must be here)
        else:  # its options: every knob's first value with the fixed ones must build it
            try:
                trial_config(estimator, space, {k.name: k.values[0] if k.values else k.low for k in space.knobs})
            except (ValueError, TypeError) as exc:
                raise UsageError(f"{space.source}: {estimator} is not trainable, so a sweep searches its options, "
                                 f"and these do not build it: {exc}") from None
        if sampler == "grid":
            space.grid()
    if args.write_artifact and is_trainable(estimator) and [k.name for k in space.knobs] == ["seed"]:
        raise UsageError(f"--write-artifact: a seed study of {estimator} installs its median-validation seed through "
                         f"training: fkn-bench train --estimator {estimator} --scenario {scenario.name} --seeds "
                         f"{' '.join(str(v) for v in space.knobs[0].values or ())} --write-artifact")
    if args.write_artifact and is_trainable(estimator):
        raise UsageError(f"--write-artifact installs the searched options of an estimator that is not trained; train "
                         f"{estimator} with the sweep's best.toml instead: fkn-bench train --estimator {estimator} "
                         f"--scenario {scenario.name} --config OUT/best.toml --write-artifact")
    study_name = args.study_name or f"{estimator}-{scenario.name}"
    with usage_errors(ValueError):
        settings = SweepSettings(
            space=space,
            scenario=scenario,
            out=output_directory(args.out if args.out is not None else Path("runs") / f"sweep-{study_name}"),
            estimator=estimator,
            sampler=sampler,
            trials=option("trials", 20),
            grid_trials=option("grid_trials"),
            top_k=option("top_k", 3),
            workers=args.workers,
            storage=args.storage,
            study_name=study_name,
            seed=option("seed", 0),
        )

    def log(message: str) -> None:
        print(message, file=sys.stderr, flush=True)

    try:
        result = run_sweep(settings, progress=not args.no_progress, log=None if args.no_progress else log)
    except SweepError as exc:
        print(f"fkn-bench sweep: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        raise Interrupted(f"the study in {storage_label(settings.storage_spec)} keeps every finished trial: run the same "
                          "command again to go on (the interrupted trials are retried, not counted)") from None
    print(f"best validation RMSE {result.best_value:.6g} ({result.best_stage} trial {result.best_number}): "
          + ", ".join(f"{k}={v}" for k, v in result.best_params.items()))
    for stage, counts in result.counts.items():
        print(f"  {stage}: " + ", ".join(f"{n} {state}" for state, n in counts.items() if n))
    for path in (result.best_config, result.trials_csv, result.figure):
        if path is not None:
            print(f"  {path}")
    if args.write_artifact:
        from fkn_bench.sweep.artifact import install_sweep_options

        print(f"  installed {install_sweep_options(settings, result)}")
    return 0
