"""``fkn-bench --help``, every subcommand's ``--help`` and ``fkn-bench scenarios`` start without
the heavy libraries (torch, numba, dask, optuna, matplotlib): issue 20, item 1 (under a second; the
imports are what took ~4 s, so the test checks the imports rather than a time)."""

from __future__ import annotations

import json
import subprocess
import sys

HEAVY = ("torch", "numba", "dask", "distributed", "optuna", "matplotlib", "scipy.signal", "minari", "h5py", "imageio")

PROBE = """
import contextlib, io, json, sys
from fkn_bench.cli import COMMANDS, build_parser, main
build_parser()
out = {"parser": sorted(m for m in %(heavy)r if m in sys.modules)}
for argv in [["--help"]] + [[name, "--help"] for name in COMMANDS] + [["scenarios"]]:
    with contextlib.redirect_stdout(io.StringIO()):
        try:
            main(argv)
        except SystemExit:
            pass
    out[" ".join(argv)] = sorted(m for m in %(heavy)r if m in sys.modules)
print(json.dumps(out))
"""


def test_help_and_scenarios_import_no_heavy_library() -> None:
    result = subprocess.run([sys.executable, "-c", PROBE % {"heavy": HEAVY}], capture_output=True, text=True, check=True)
    imported = json.loads(result.stdout.strip().splitlines()[-1])
    assert imported == {key: [] for key in imported}, {k: v for k, v in imported.items() if v}
    assert len(imported) >= 12  # the parser, --help, ten subcommands' --help, scenarios
