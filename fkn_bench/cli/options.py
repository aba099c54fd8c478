"""Command-line options shared by several subcommands."""

from __future__ import annotations

import argparse

__all__ = ["add_scenario_file_option", "load_scenario_files"]


def add_scenario_file_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--scenario-file",
        action="append",
        default=[],
        metavar="TOML",
        help="register the [scenario.NAME] tables of this TOML file first (repeatable)",
    )


def load_scenario_files(args: argparse.Namespace) -> None:
    from fkn_bench.scenarios import load_scenarios

    for path in getattr(args, "scenario_file", []) or []:
        load_scenarios(path)
