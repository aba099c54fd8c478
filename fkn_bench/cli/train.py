"""``fkn-bench train``: fit a trainable estimator (FlexKalmanNet, the tuned baselines, any registered
with a ``Trainable`` declaration) to a scenario.

Writes a checkpoint, the training history (CSV), the two training figures (PNG) and the learned
parameters (JSON) into ``--out`` (default ``runs/<estimator>-<scenario>``); ``--write-artifact``
also installs the parameters as the committed artefact the estimator runs from by default
(``<estimator>-<family>.json`` in the ``params/`` folder of the package that the estimator's
registration names: ``fkn_bench/flexkalmannet/params``, ``fkn_bench/kalmannet/params``,
``baselines/params``). Repeat ``--scenario`` to train on a mixture of scenarios; ``--family``
names the family the artefact is for (``default``: recordings and user scenarios). ``--model``
picks the filter's process model. Examples::

    fkn-bench train --estimator flexkalmannet --scenario ds1 --write-artifact
    fkn-bench train --estimator flexkalmannet --model rigid-body-ratios --scenario tumble-fast \\
        --scenario tumble-flip --scenario tumble-slow --family tumble

``--seeds 0 1 2`` is a training-seed study (:mod:`fkn_bench.training.seeds`): the configuration
trained once per seed into ``OUT/seed-<K>/``, the study in ``OUT/seed_study.json`` and ``.csv``,
and the seed of the median validation RMSE chosen (the test split is never read by the choice);
with ``--write-artifact`` the chosen run is installed with the study in its record and the other
seeds under ``params/seeds/``, where the leaderboards' training-seed spread comes from::

    fkn-bench train --estimator flexkalmannet --scenario spin --seeds 0 1 2 --write-artifact
    fkn-bench train --estimator kalmannet --scenario spin --config fkn_bench/kalmannet/params/kalmannet-spin.json \\
        --seeds 0 1 2 --write-artifact     # the committed configuration, again
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

from fkn_bench.cli import Interrupted, UsageError, usage_errors
from fkn_bench.cli.options import (add_command, add_scenario_file_option, check_minimum, load_scenario_files, output_directory,
                                   parse_key_values)

__all__ = ["add_parser", "parse_options"]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(subparsers, "train",
                         "train a trainable estimator (FlexKalmanNet, the tuned baselines)", __doc__)
    parser.add_argument("--estimator", default="flexkalmannet", help="trainable estimator (default: flexkalmannet)")
    parser.add_argument("--scenario", action="append", default=None,
                        help="training scenario (default: ds1); repeat it to train on a mixture of scenarios")
    parser.add_argument("--family", help="model family of the artefact (default: the scenarios' common family, "
                                         "else 'default': the artefact used where no family applies)")
    parser.add_argument("--filter", dest="variant", choices=("ekf", "ukf", "mekf"), help="filter variant")
    parser.add_argument("--model", dest="process_model", metavar="MODEL",
                        help="process model, any registered in fkn_bench.models (built in: constant-velocity, "
                             "the paper's; rigid-body, the scenario's inertia; rigid-body-ratios, inertia ratios estimated)")
    parser.add_argument("--objective", choices=("supervised", "nll", "gaussian-nll"),
                        help="training objective (gaussian-nll: estimators with a covariance of their own, "
                             "recursive-kalmannet and cholesky-kalmannet)")
    parser.add_argument("--config", metavar="TOML|JSON",
                        help="configuration file (options below override it), or a learned-parameter file "
                             "(params/<estimator>-<family>.json) whose training configuration to train with again")
    parser.add_argument("--epochs", type=int, help="maximum epochs")
    parser.add_argument("--lr", type=float, help="learning rate")
    parser.add_argument("--seed", type=int, help="random seed")
    parser.add_argument("--seeds", type=int, nargs="+", metavar="K",
                        help="a training-seed study: train once per seed K, choose the median-validation seed")
    parser.add_argument("--device", help="where the network, the data and the filter run: cpu (default) or cuda "
                                         "(a GPU; the window order is drawn on the CPU, so a seed trains on the same windows)")
    parser.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE",
        help="any other config field, e.g. --set hidden=256 --set learn=q_std,r_std (repeatable)",
    )
    parser.add_argument("--out", type=Path, help="output directory (default: runs/<estimator>-<scenario>)")
    parser.add_argument("--resume", action="store_true", help="continue from the checkpoint in --out")
    parser.add_argument("--write-artifact", action="store_true", help="install the learned parameters as the committed default")
    parser.add_argument("--json", action="store_true", help="print the summary as one JSON document")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_scenario_file_option(parser)
    parser.set_defaults(handler=run)


def parse_options(args: argparse.Namespace) -> dict[str, Any]:
    """Config overrides from the named options and ``--set KEY=VALUE`` pairs."""
    options = parse_key_values(args.set, "--set")
    for name in ("variant", "process_model", "objective", "epochs", "lr", "seed", "device", "config"):
        value = getattr(args, name)
        if value is not None:
            options[name] = value
    return options


def run(args: argparse.Namespace) -> int:
    from fkn_bench.estimators import UnknownEstimatorError
    from fkn_bench.scenarios import get_scenario
    from fkn_bench.training import fit
    from fkn_bench.training.pipeline import CHECKPOINT_INTERVAL_S

    check_minimum(args, epochs=1, seed=0)
    if args.lr is not None and not (math.isfinite(args.lr) and args.lr > 0):
        raise UsageError(f"--lr must be a finite number > 0 (got {args.lr:g})")
    load_scenario_files(args)
    scenarios = [get_scenario(name) for name in (args.scenario or ["ds1"])]
    label = "+".join(s.name for s in scenarios)
    if args.seeds is not None:
        return _seed_study(args, scenarios, label)
    out = output_directory(args.out if args.out is not None else Path("runs") / f"{args.estimator}-{label}")
    started = time.time()
    try:
        with usage_errors(UnknownEstimatorError, ValueError, TypeError):
            outcome = fit(args.estimator, scenarios, parse_options(args), out=out, resume=args.resume,
                          progress=not args.no_progress, family=args.family)
    except KeyboardInterrupt:
        saved = Path(out) / "checkpoint.pt"
        if not (saved.is_file() and saved.stat().st_mtime >= started):  # (not an earlier run's)
            raise
        raise Interrupted(f"{out / 'checkpoint.pt'} holds the last saved epoch (checkpoints are written at most "
                          f"{CHECKPOINT_INTERVAL_S:g} s apart): add --resume to the same command to continue from it") from None
    summary = outcome.summary()
    if args.write_artifact:
        from fkn_bench.training.artifacts import install_artifact

        summary["installed_artifact"] = str(install_artifact(summary["artifact"], args.estimator, summary["family"]))
    if args.json:
        print(json.dumps(summary, indent=2, default=str))
        return 0
    print(f"trained {summary['estimator']} on {summary['scenario']}: {summary['epochs_run']} epochs, "
          f"best epoch {summary['best_epoch']}, {summary['seconds']:.1f} s")
    if "test_rmse" in summary:
        print(f"  test 13-state RMSE {summary['test_rmse']:.5f} (test split of seed {summary.get('test_seed')})")
    written = [p.name for p in sorted(Path(summary["out"]).iterdir()) if p.suffix in (".pt", ".csv", ".png", ".json")]
    print(f"  outputs in {summary['out']} ({', '.join(written)})")
    if "installed_artifact" in summary:
        print(f"  installed {summary['installed_artifact']}")
    sys.stdout.flush()
    return 0


def _seed_study(args: argparse.Namespace, scenarios: list[Any], label: str) -> int:
    """``--seeds``: a training-seed study (module docstring)."""
    from fkn_bench.estimators import UnknownEstimatorError
    from fkn_bench.training.seeds import install_seed_study, train_seeds

    if args.seed is not None:
        raise UsageError("give either --seed or --seeds, not both")
    if min(args.seeds) < 0 or len(set(args.seeds)) != len(args.seeds):
        raise UsageError(f"--seeds must be distinct integers >= 0 (got {' '.join(map(str, args.seeds))})")
    out = output_directory(args.out if args.out is not None else Path("runs") / f"{args.estimator}-{label}-seeds")
    with usage_errors(UnknownEstimatorError, ValueError, TypeError):
        study = train_seeds(args.estimator, scenarios, parse_options(args), args.seeds, out=out, family=args.family,
                            resume=args.resume, progress=not args.no_progress,
                            log=None if args.json else lambda line: print(line, flush=True))
    document = study.to_dict()
    if args.write_artifact:
        document["installed"] = [str(p) for p in install_seed_study(study)]
    if args.json:
        print(json.dumps(document, indent=2, default=str))
        return 0
    for run in study.runs:
        test = "" if run.test_rmse is None else f", test {run.test_rmse:.5f}"
        mark = "  <- chosen (median validation)" if run.seed == study.chosen else ""
        shown = f"validation {run.val_rmse:.5f}{test}" if run.status == "ok" else f"failed: {run.error}"
        print(f"  seed {run.seed}: {shown}{mark}")
    print(f"  study in {out / 'seed_study.json'}")
    for path in document.get("installed", ()):
        print(f"  installed {path}")
    sys.stdout.flush()
    return 0
