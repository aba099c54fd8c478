"""``fkn-bench scenarios``: list the registered scenarios (the prior families first, each episode
drawing its own truth; then the paper's fixed-truth scenarios and the others), or show one in full
with its stated prior."""

from __future__ import annotations

import argparse
import json
from typing import Any

from fkn_bench.cli.options import add_scenario_file_option, load_scenario_files

__all__ = ["add_parser"]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("scenarios", help="list the named scenarios", description=__doc__)
    parser.add_argument("name", nargs="?", help="show this scenario's full configuration")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    add_scenario_file_option(parser)
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from fkn_bench.scenarios import get_scenario, list_scenarios

    load_scenario_files(args)
    if args.name:  # one scenario: its configuration, key by key
        scenario = get_scenario(args.name)
        prior = scenario.describe_prior()
        lines = scenario.to_dict() | {"config_hash": scenario.config_hash()} | {f"prior.{k}": v for k, v in prior.items()}
        document: Any = scenario.to_dict() | {"config_hash": scenario.config_hash(), "prior": prior}
    else:  # every scenario: name and description
        scenarios = sorted(list_scenarios(), key=lambda s: "prior" not in s.tags)  # stable: registration order within
        document = [s.to_dict() for s in scenarios]
        lines = {s.name: s.description for s in scenarios}
    if args.json:
        print(json.dumps(document, indent=2))
        return 0
    width = max(len(key) for key in lines)
    for key, value in lines.items():
        print(f"{key:<{width}}  {value}")
    return 0
