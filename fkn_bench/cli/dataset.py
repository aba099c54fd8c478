"""``fkn-bench dataset``: write a scenario's episodes as a Minari dataset (Farama's format for
datasets recorded from Gymnasium environments).

One Minari episode per seed, as ``AstrobeeTumble-v0`` reset with that seed gives it: the pose
observations, the actions of a behaviour estimator (``--estimator``, default the paper's manual
EKF) and their rewards, the true state in ``infos["truth"]``; the scenario, split, seeds and
provenance in the dataset's metadata (``fkn_bench.exporters.datasets``). Score any estimator on it
with ``fkn-bench run --dataset DIR/ID`` (the same scores as on the scenario), or load it with
Minari: ``MINARI_DATASETS_PATH=DIR`` and ``minari.load_dataset(ID)``.

The dataset is built in a hidden scratch directory inside DIR and moved into place when complete,
with the SHA-256 checksums of its files, which ``run --dataset`` checks before scoring. Exit code 2,
with one line naming the problem: an ID that is not Minari's ``NAME-vN`` or ``NAMESPACE/NAME-vN``
(refused before anything is written), an existing dataset of that ID (replace it with ``--force``),
DIR in use by another ``fkn-bench dataset``, too little free space for the dataset (checked up
front, from its estimated size) or a failed write. An interrupted command leaves no dataset
behind; run it again.

Examples::

    fkn-bench dataset --scenario ds1 --seeds 20 --out datasets          # datasets/fkn-bench/ds1-full-v0
    fkn-bench run --dataset datasets/fkn-bench/ds1-full-v0 --estimator flexkalmannet
    fkn-bench dataset --scenario tumble-fast --seeds 5 --split test --out datasets
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fkn_bench.cli import UsageError, usage_errors
from fkn_bench.cli.options import add_command, add_scenario_file_option, check_minimum, load_scenario_files

__all__ = ["add_parser"]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    from fkn_bench.scenarios import SPLITS

    parser = add_command(subparsers, "dataset", "write a scenario's episodes as a Minari dataset", __doc__)
    parser.add_argument("--scenario", default="ds1", help="scenario (default: ds1)")
    parser.add_argument("--seeds", type=int, default=20, metavar="N", help="episodes of seeds 0 .. N-1 (default: 20)")
    parser.add_argument("--split", default="full", choices=SPLITS,
                        help="whole episodes (default) or one split of each")
    parser.add_argument("--estimator", default="manual-ekf",
                        help="behaviour estimator whose estimates are the actions (default: manual-ekf)")
    parser.add_argument("--out", required=True, type=Path, metavar="DIR",
                        help="datasets directory (Minari's MINARI_DATASETS_PATH); the dataset is DIR/ID")
    parser.add_argument("--dataset-id", metavar="ID",
                        help="Minari dataset id, NAME-vN or NAMESPACE/NAME-vN (default: fkn-bench/<scenario>-<split>-v0)")
    parser.add_argument("--force", action="store_true", help="replace an existing dataset of that id")
    add_scenario_file_option(parser)
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from fkn_bench.estimators import UnknownEstimatorError
    from fkn_bench.exporters import write_dataset
    from fkn_bench.scenarios import get_scenario

    check_minimum(args, seeds=1)
    if args.out.exists() and not args.out.is_dir():
        raise UsageError(f"--out: {args.out} is a file, not a directory")
    load_scenario_files(args)
    scenario = get_scenario(args.scenario)
    with usage_errors(UnknownEstimatorError, ValueError, OSError):  # (an existing dataset: FileExistsError)
        path = write_dataset(scenario, range(args.seeds), args.out, split=args.split, estimator=args.estimator,
                             dataset_id=args.dataset_id, force=args.force)
    dataset_id = path.relative_to(args.out).as_posix()
    print(f"wrote {path}: {args.seeds} episode(s) of {scenario.name} ({args.split}), actions by {args.estimator}",
          file=sys.stderr)
    print(f"  score an estimator on it: fkn-bench run --dataset {path} --estimator NAME", file=sys.stderr)
    print(f"  load it with Minari: MINARI_DATASETS_PATH={args.out} python -c \"import minari; "
          f"print(minari.load_dataset('{dataset_id}'))\"", file=sys.stderr)
    return 0
