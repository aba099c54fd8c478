"""``fkn-bench record``: write an episode and an estimator's estimates to an MCAP file.

The file is a ROS 2 MCAP (profile "ros2", CDR messages of standard geometry_msgs types) for ROS 2
tools with rosbag2's MCAP storage plugin (``ros2 bag info run.mcap``) and for Foxglove (3-D panel,
display frame "world"); topics, frames and conventions are listed in
:mod:`fkn_bench.recordings.writer`. The file is written atomically; an existing ``--out`` file is
never replaced without ``--force``. Example::

    fkn-bench record --scenario ds1 --estimator manual-ekf --seed 0 --out run.mcap
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from fkn_bench.cli import UsageError
from fkn_bench.cli.options import add_command, add_scenario_file_option, check_minimum, load_scenario_files

__all__ = ["add_parser"]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(subparsers, "record", "record an episode and its estimates as MCAP (ROS 2 + Foxglove)", __doc__)
    parser.add_argument("--scenario", default="ds1", help="scenario name (default: ds1)")
    parser.add_argument("--estimator", default="manual-ekf",
                        help="registered estimator name, a saved estimator (.json), or 'none' for truth and "
                             "measurements only (default: manual-ekf)")
    parser.add_argument("--seed", type=int, default=0, help="episode seed (default: 0)")
    parser.add_argument("--split", default="full", choices=("full", "train", "val", "test"))
    parser.add_argument("--steps", type=int, default=None, metavar="N", help="record only the first N steps")
    parser.add_argument("--out", required=True, type=Path, metavar="FILE.mcap",
                        help="output file (an existing file is refused unless --force)")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file")
    parser.add_argument("--namespace", default="", help="topic namespace, e.g. /honey (default: none)")
    parser.add_argument("--no-foxglove", action="store_true", help="omit the foxglove.PoseInFrame channels")
    parser.add_argument("--compression", default="zstd", choices=("zstd", "lz4", "none"), help="chunk compression")
    parser.add_argument("--json", action="store_true", help="print a JSON summary")
    add_scenario_file_option(parser)
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from fkn_bench.estimators import EstimatorFileError, UnknownEstimatorError
    from fkn_bench.exporters.recording import record
    from fkn_bench.io import WriteError, remove_temporaries
    from fkn_bench.scenarios import get_scenario

    check_minimum(args, seed=0, steps=1)
    load_scenario_files(args)
    scenario = get_scenario(args.scenario)  # unknown names exit with code 2 and the list
    if args.out.exists() and args.out.is_dir():
        raise UsageError(f"--out {args.out} is a directory; give a file name such as run.mcap")
    if (args.out.exists() or args.out.is_symlink()) and not args.force:
        raise UsageError(f"--out {args.out} exists; choose another file name, or pass --force to replace it")
    if any(c.isspace() for c in args.namespace):
        raise UsageError(f"--namespace must not contain spaces (got {args.namespace!r})")
    estimator = None if args.estimator.lower() == "none" else args.estimator
    if estimator is not None and estimator.endswith(".json") and not Path(estimator).is_file():
        raise UsageError(f"estimator file not found: {estimator}")
    remove_temporaries(args.out.parent, recursive=False, target=args.out.name)  # a killed record's leftovers
    try:
        summary = record(args.out, scenario=scenario, estimator=estimator, seed=args.seed, split=args.split,
                         n_steps=args.steps, namespace=args.namespace, foxglove=not args.no_foxglove,
                         compression=args.compression)
    except (UnknownEstimatorError, EstimatorFileError) as exc:
        raise UsageError(str(exc)) from None
    except WriteError:  # one line naming the file (and the free space, when the disk is full)
        raise
    except OSError as exc:  # an unwritable place, a missing parent directory
        raise UsageError(f"cannot write {args.out}: {exc.strerror or exc}") from None
    if args.json:
        print(json.dumps({
            "path": str(summary.path),
            "scenario": scenario.name,
            "estimator": estimator,
            "seed": args.seed,
            "steps": summary.n_steps,
            "messages": summary.message_counts,
            "size_bytes": summary.size_bytes,
            "write_seconds": summary.write_seconds,
            **summary.timings,
        }, indent=2))
        return 0
    print(f"wrote {summary.path}: {summary.n_steps} steps of {scenario.name} (seed {args.seed}), "
          f"{summary.message_count} messages on {len(summary.message_counts)} topics, "
          f"{summary.size_bytes / 1e6:.2f} MB in {summary.write_seconds:.2f} s")
    width = max(len(t) for t in summary.message_counts)
    for topic, count in summary.message_counts.items():
        print(f"  {topic:<{width}}  {count}")
    return 0
