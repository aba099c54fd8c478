"""``fkn-bench bench``: speed measurements that print ratios measured in one run.

``fkn-bench bench train`` times one epoch of FlexKalmanNet's batched trainer and one epoch of the
sequential reference trainer (windows one after another, the network at every step) on the same
data and configuration, and prints both and their ratio.
"""

from __future__ import annotations

import argparse
import json

from fkn_bench.cli import UsageError

__all__ = ["add_parser"]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("bench", help="speed benchmarks (ratios measured in one run)", description=__doc__)
    kinds = parser.add_subparsers(dest="bench", metavar="WHAT", required=True)
    train = kinds.add_parser("train", help="batched trainer vs the sequential reference, one epoch each")
    train.add_argument("--scenario", default="ds1")
    train.add_argument("--paper-windows", action="store_true", help="the paper's 512-sample windows with a measurement every step")
    train.add_argument("--reference-windows", type=int, help="time only this many reference windows and scale to an epoch")
    train.add_argument("--trainer-epochs", type=int, default=3, help="trainer epochs timed (median reported)")
    train.add_argument("--json", action="store_true")
    train.set_defaults(handler=run_train)


def run_train(args: argparse.Namespace) -> int:
    from fkn_bench.flexkalmannet.benchmark import measure_training_speed
    from fkn_bench.flexkalmannet.config import FlexKalmanNetConfig

    if args.reference_windows is not None and args.reference_windows < 1:
        raise UsageError("--reference-windows must be >= 1")
    config = FlexKalmanNetConfig()
    if args.paper_windows:
        config = config.replace(window=512, stride=None, train_measurement_every=1)
    speed = measure_training_speed(args.scenario, config, reference_windows=args.reference_windows, trainer_epochs=args.trainer_epochs)
    if args.json:
        print(json.dumps(speed.to_dict(), indent=2))
        return 0
    timed = "" if speed.reference_windows_timed == speed.windows else f" (timed {speed.reference_windows_timed} of {speed.windows} windows, scaled)"
    print(f"FlexKalmanNet training speed on {speed.scenario}: {speed.windows} windows of {speed.window} samples, "
          f"a measurement every {speed.train_measurement_every} step(s)")
    print(f"  sequential reference  {speed.reference_seconds_per_epoch:8.2f} s/epoch{timed}")
    print(f"  batched trainer       {speed.trainer_seconds_per_epoch:8.2f} s/epoch (median of {speed.trainer_epochs_timed})")
    print(f"  ratio                 {speed.ratio:8.1f}x")
    return 0
