"""``fkn-bench reproduce``: regenerate every table and figure of the FlexKalmanNet paper's results
section from scratch (simulated data, training on ds1 and ds2, evaluation) and write a report:
``OUT/index.md`` and ``OUT/index.html`` with the paper's quoted numbers beside ours, the figures
(``OUT/figures/*.png``), one CSV per table (``OUT/tables``), ``OUT/results.json`` and the trained
models (``OUT/training/<data set>``).

Deterministic for a given ``--seed``. ``--quick`` runs the same pipeline with a much smaller
network, a few epochs and 5 evaluation seeds (well under two minutes; labelled QUICK in the
report). ``--config TOML`` trains with another configuration, e.g. the ``best.toml`` of
``fkn-bench sweep``.

Examples::

    fkn-bench reproduce                 # report in runs/reproduce/index.md
    fkn-bench reproduce --quick --out /tmp/reproduce-quick
"""

from __future__ import annotations

import argparse
from pathlib import Path

from fkn_bench.cli import usage_errors
from fkn_bench.cli.options import add_command, check_minimum, output_directory

__all__ = ["add_parser", "run"]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(subparsers, "reproduce", "regenerate the paper's tables and figures and write a report", __doc__)
    parser.add_argument("--out", type=Path, metavar="DIR",
                        help="report directory (default: runs/reproduce, with --quick runs/reproduce-quick)")
    parser.add_argument("--quick", action="store_true", help="small network, few epochs, 5 seeds: a pipeline check")
    parser.add_argument("--seed", type=int, default=0, help="training seed (default: 0, the paper's)")
    parser.add_argument("--seeds", type=int, metavar="N",
                        help="test-split seeds per evaluation (default: 20; 5 with --quick)")
    parser.add_argument("--config", type=Path, metavar="TOML",
                        help="training configuration file (default: FlexKalmanNetConfig's defaults)")
    parser.add_argument("--no-figures", action="store_true",
                        help="tables, report and results.json only, no figures (about 40%% faster)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars or stage messages")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from fkn_bench.flexkalmannet import FlexKalmanNetConfig
    from fkn_bench.reproduce import ReproduceSettings, run_reproduction
    from fkn_bench.reproduce.pipeline import stderr_log
    from fkn_bench.runtime import resolve_device

    check_minimum(args, seed=0, seeds=1)
    with usage_errors(ValueError, TypeError):
        config = FlexKalmanNetConfig.from_toml(args.config) if args.config is not None else None
        settings = ReproduceSettings(seed=args.seed, eval_seeds=args.seeds, quick=args.quick, config=config,
                                     config_source=str(args.config) if args.config is not None else None,
                                     figures=not args.no_figures)
        resolve_device(settings.training_config().device)  # (a GPU the config names must be here)
    out = output_directory(args.out if args.out is not None else Path("runs") / ("reproduce-quick" if args.quick else "reproduce"))
    reproduction = run_reproduction(out, settings, progress=not args.no_progress,
                                    log=None if args.no_progress else stderr_log)
    print(reproduction.out / "index.md")
    print(reproduction.out / "index.html")
    return 0
