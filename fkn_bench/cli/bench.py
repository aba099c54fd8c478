"""``fkn-bench bench``: speed measurements.

* ``fkn-bench bench run``: run the pytest-benchmark speed suite (``tests/benchmarks`` of a source
  checkout), save its JSON (with machine info) and print the summary table;
* ``fkn-bench bench report FILE.json``: the summary table of a saved pytest-benchmark JSON: per
  benchmark the rounds, median and mean time, spread, the throughput in steps/s from the
  ``steps`` each benchmark records in ``extra_info``, and for a batched filter benchmark (one that
  records its ``batch``) the fraction of the *small-bmm limit* at that batch measured in the same
  run (:data:`MATMULS_PER_STEP`);
* ``fkn-bench bench compile``: compile the EKF's numba kernels now (about 45 s in a fresh
  environment; numba's disk cache keeps them for every later process);
* ``fkn-bench bench gate``: the CI speed-ratio gate (:mod:`fkn_bench.gates.speed`): each check's
  ratio against the reference timed beside it, its threshold and verdict; with ``--trips`` also
  each hotspot made to do its work twice, which must fail (the test command runs
  ``fkn-bench bench gate --trips`` after pytest: timed checks are a benchmark, not a test);
* ``fkn-bench bench train``: one epoch of FlexKalmanNet's batched trainer against one epoch of
  the sequential reference trainer (windows one after another, the network at every step) on the
  same data and configuration, and their ratio; with ``--time-varying`` also the trainer's epoch in
  time-varying mode against the constant mode, timed alternately.

Examples::

    fkn-bench bench run --json bench.json          # the whole suite (a few minutes)
    fkn-bench bench run -k "filter or online"      # a part of it
    fkn-bench bench report bench.json
    fkn-bench bench gate --check ekf-forward --check train-epoch
    fkn-bench bench gate --trips                   # CI: every check, and every hotspot doubled fails
    fkn-bench bench gate --check online-step:my-filter --calibrate 10   # ratios and a threshold
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

from fkn_bench.cli import UsageError

from fkn_bench.cli.options import add_command

__all__ = ["add_parser", "summarize_benchmarks", "format_summary", "MATMULS_PER_STEP"]

MATMULS_PER_STEP = 2
"""Batched 13 x 13 float64 matrix products per filter step that the *small-bmm limit* assumes:
the two of a dense ``F P F^T`` (one predict); a measurement update, the mean and everything else
count as free. The speed suite times ``torch.bmm`` of ``(B, 13, 13)`` float64 batches on one
thread at each batch size it runs a filter at (``test_small_bmm_limit``, ``extra_info``
``small_bmm_limit: true``, ``batch: B`` and ``steps = B / MATMULS_PER_STEP`` per product), so
that benchmark's steps/s *is* the limit ``B / (MATMULS_PER_STEP * t_bmm)``; the report divides each
batched filter benchmark's steps/s (``extra_info`` ``batch``) by the limit at its batch from the same
run. A structured step (:mod:`fkn_bench.filters.structured`) needs fewer products than two
dense ones, so a fraction above 1 is possible: the limit is a yardstick of how far the code is
from the machine's small-matrix speed, not a bound."""


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(subparsers, "bench", "speed benchmarks, their summary and the CI speed gate", __doc__)
    kinds = parser.add_subparsers(dest="bench", metavar="WHAT", required=True)

    run = kinds.add_parser("run", help="run the pytest-benchmark speed suite and print its summary")
    run.add_argument("--json", default="bench.json", metavar="FILE",
                     help="where pytest-benchmark writes its results (default: bench.json)")
    run.add_argument("-k", dest="keyword", metavar="EXPR", help="only benchmarks matching this pytest -k expression")
    run.add_argument("--device", default="cpu", help="where the batched filter and training benchmarks run: cpu "
                                                     "(default) or cuda (a GPU)")
    run.add_argument("--large-batch", type=int, default=1024, metavar="B",
                     help="the filter core's large batch (default 1024; the benchmarks keep their batch_1024 names)")
    run.add_argument("--suite", metavar="DIR",
                     help="the suite's directory (default: tests/benchmarks here or in the source checkout)")
    run.set_defaults(handler=run_suite)

    report = kinds.add_parser("report", help="summary table (throughputs) of a pytest-benchmark JSON file")
    report.add_argument("file", metavar="FILE.json")
    report.add_argument("--json", action="store_true", help="print the summary as JSON")
    report.set_defaults(handler=run_report)

    compile_ = kinds.add_parser("compile", help="compile the EKF's numba kernels now (cached on disk for later runs)")
    compile_.set_defaults(handler=run_compile)
    gate = kinds.add_parser("gate", help="the CI speed-ratio gate: ratios against references timed beside them")
    gate.add_argument("--check", action="append", metavar="NAME", help="only this check (repeatable; default: all)")
    gate.add_argument("--attempts", type=int, default=3, help="measurements before a check fails (default: 3)")
    gate.add_argument("--list", action="store_true", help="list the checks and thresholds, measure nothing")
    gate.add_argument("--calibrate", type=int, metavar="N",
                      help="measure each check N times and with its work doubled; print the ratios and a threshold")
    gate.add_argument("--trips", action="store_true",
                      help="also show that the gate works: each hotspot made to do its work twice must fail "
                           "(one check per hotspot; exit 1 when a doubled hotspot passes)")
    gate.add_argument("--json", action="store_true")
    gate.set_defaults(handler=run_gate)

    train = kinds.add_parser("train", help="batched trainer vs the sequential reference, one epoch each")
    train.add_argument("--scenario", default="ds1")
    train.add_argument("--paper-windows", action="store_true", help="the paper's 512-sample windows with a measurement every step")
    train.add_argument("--reference-windows", type=int, help="time only this many reference windows and scale to an epoch")
    train.add_argument("--trainer-epochs", type=int, default=3, help="trainer epochs timed (median reported)")
    train.add_argument("--time-varying", action="store_true",
                       help="also time the trainer in time-varying mode and print its ratio to the constant mode")
    train.add_argument("--device", default="cpu", help="where the batched trainer runs (cpu, default, or cuda); "
                                                       "the sequential reference runs on the CPU")
    train.add_argument("--json", action="store_true")
    train.set_defaults(handler=run_train)


# ---------------------------------------------------------------------------------- report
def _load_benchmarks(path: str | Path) -> dict[str, Any]:
    try:
        document = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise UsageError(f"benchmark file not found: {path}") from None
    except (OSError, ValueError) as exc:
        raise UsageError(f"{path} is not a readable JSON file: {exc}") from None
    if not isinstance(document, dict) or not isinstance(document.get("benchmarks"), list):
        raise UsageError(f"{path} is not a pytest-benchmark JSON file (no 'benchmarks' list; write one with --benchmark-json)")
    return document


def summarize_benchmarks(document: dict[str, Any]) -> list[dict[str, Any]]:
    """One row per benchmark of a pytest-benchmark JSON document: name, rounds, median, mean,
    min and standard deviation (s), ``steps`` per call (``extra_info``) and steps/s (from the
    median: the least disturbed by a busy machine but for the minimum, and steadier than it);
    ``batch`` and ``of_bmm_limit``: a batched benchmark's batch size and its steps/s over the
    small-bmm limit at that batch in the same document (:data:`MATMULS_PER_STEP`; None without
    one)."""
    rows = []
    for bench in document["benchmarks"]:
        stats = bench.get("stats", {})
        extra = bench.get("extra_info", {}) or {}
        times = {f"{k}_s": float(stats.get(k, math.nan)) for k in ("median", "mean", "min", "stddev")}
        median = times["median_s"]
        steps = extra.get("steps")
        rows.append({
            "name": bench.get("name", "?"),
            "group": bench.get("group"),
            "rounds": int(stats.get("rounds", 0)),
            **times,
            "steps": int(steps) if steps is not None else None,
            "steps_per_s": (int(steps) / median) if steps and median > 0 else None,
            "what": extra.get("what", ""),
            "batch": int(extra["batch"]) if extra.get("batch") is not None else None,
            "small_bmm_limit": bool(extra.get("small_bmm_limit", False)),
        })
    limits = {row["batch"]: row["steps_per_s"] for row in rows if row["small_bmm_limit"] and row["steps_per_s"]}
    for row in rows:
        limit = limits.get(row["batch"]) if not row["small_bmm_limit"] else None
        row["of_bmm_limit"] = row["steps_per_s"] / limit if limit and row["steps_per_s"] is not None else None
    return rows


def _scaled(value: float | None, units: tuple[tuple[str, float], ...]) -> str:
    """Three significant digits in the first of ``units`` (largest first) that ``value`` reaches,
    else in the last; ``-`` for a missing value."""
    if value is None or not math.isfinite(value):
        return "-"
    unit, scale = next(((u, s) for u, s in units if value >= s), units[-1])
    return f"{value / scale:.3g} {unit}".rstrip()


_SECONDS = (("s", 1.0), ("ms", 1e-3), ("us", 1e-6), ("ns", 1e-9))
_RATE = (("G", 1e9), ("M", 1e6), ("k", 1e3), ("", 1.0))


def _machine(document: dict[str, Any]) -> str:
    machine = document.get("machine_info", {}) or {}
    cpu = machine.get("cpu", {}) or {}
    commit = document.get("commit_info", {}) or {}
    parts = [
        machine.get("machine") or "?",
        cpu.get("brand_raw") or machine.get("processor") or "unknown CPU",
        f"{cpu.get('count', '?')} CPUs",
        f"{machine.get('python_implementation', 'Python')} {machine.get('python_version', '?')}",
    ]
    text = "machine: " + ", ".join(str(p) for p in parts)
    if commit.get("id"):
        text += f"; commit {str(commit['id'])[:12]}{' (dirty)' if commit.get('dirty') else ''}"
    return text


def format_summary(document: dict[str, Any], *, source: str = "") -> str:
    """The summary table of :func:`summarize_benchmarks` as text, with the machine."""
    from fkn_bench.reporting.report import text_table

    rows = summarize_benchmarks(document)
    header = ("benchmark", "rounds", "median", "mean", "stddev", "steps", "steps/s", "of limit", "what")
    body = []
    for row in rows:
        spread = f"{100 * row['stddev_s'] / row['mean_s']:.0f}%" if row["mean_s"] and math.isfinite(row["stddev_s"]) else "-"
        body.append((row["name"], str(row["rounds"]), _scaled(row["median_s"], _SECONDS), _scaled(row["mean_s"], _SECONDS),
                     spread, "-" if row["steps"] is None else str(row["steps"]), _scaled(row["steps_per_s"], _RATE),
                     "-" if row["of_bmm_limit"] is None else f"{row['of_bmm_limit']:.2f}", row["what"]))
    title = f"fkn-bench speed suite{': ' + source if source else ''} (pytest-benchmark {document.get('version', '?')}"
    title += f", {document.get('datetime', '?')})"
    note = ("Times are wall-clock per call; steps/s = steps per call / median. Absolute times vary by "
            "tens of percent between runs on shared machines: compare ratios within one run "
            "(fkn-bench bench gate). 'of limit': a batched filter's steps/s over the small-bmm limit "
            f"at its batch timed in this run ({MATMULS_PER_STEP} batched 13x13 float64 products per step).")
    return "\n".join([title, _machine(document), "", text_table(header, body, right=range(1, 8)), "",
                      note])


def run_report(args: argparse.Namespace) -> int:
    document = _load_benchmarks(args.file)
    if args.json:
        print(json.dumps({"file": args.file, "machine_info": document.get("machine_info"),
                          "commit_info": document.get("commit_info"), "benchmarks": summarize_benchmarks(document)},
                         indent=2))
    else:
        print(format_summary(document, source=args.file))
    return 0


# ---------------------------------------------------------------------------------- run
def _suite_directory(given: str | None) -> Path:
    if given is not None:
        path = Path(given)
        if not path.is_dir():
            raise UsageError(f"benchmark suite not found: {path}")
        return path.resolve()
    import fkn_bench

    for candidate in (Path.cwd() / "tests" / "benchmarks", Path(fkn_bench.__file__).resolve().parents[1] / "tests" / "benchmarks"):
        if candidate.is_dir():
            return candidate.resolve()
    raise UsageError("the speed suite (tests/benchmarks) is part of the source checkout: run this from the "
                     "repository root, or pass --suite DIR")


def run_suite(args: argparse.Namespace) -> int:
    from fkn_bench.runtime import resolve_device

    suite = _suite_directory(args.suite)
    try:
        device = resolve_device(args.device)
    except ValueError as error:
        raise UsageError(str(error)) from None
    if args.large_batch < 1:
        raise UsageError("--large-batch must be >= 1")
    environment = {**os.environ, "FKN_BENCH_DEVICE": str(device), "FKN_BENCH_LARGE_BATCH": str(args.large_batch)}
    output = Path(args.json).resolve()
    command = [sys.executable, "-m", "pytest", str(suite), "-n", "0", "--benchmark-only", f"--benchmark-json={output}",
               "-q", "-p", "no:cacheprovider"]
    if args.keyword:
        command += ["-k", args.keyword]
    print(f"fkn-bench bench run: {' '.join(command)}", file=sys.stderr)
    code = subprocess.call(command, cwd=suite.parents[1], env=environment)
    if output.is_file():
        print(format_summary(_load_benchmarks(output), source=str(args.json)))
    return code


# ---------------------------------------------------------------------------------- compile
def run_compile(args: argparse.Namespace) -> int:
    """Compile (or load from numba's cache) every kernel of :mod:`fkn_bench.filters.kernels`."""
    import time

    from fkn_bench.filters import kernels

    start = time.perf_counter()
    try:
        compiled = kernels.warm_up()
    except RuntimeError as exc:
        raise UsageError(str(exc)) from None
    print(f"fkn-bench bench compile: {len(compiled)} kernels ready ({', '.join(compiled)}) in "
          f"{time.perf_counter() - start:.1f} s", file=sys.stderr)
    return 0


# ---------------------------------------------------------------------------------- gate
def run_gate(args: argparse.Namespace) -> int:
    from fkn_bench.gates import speed

    if args.attempts < 1:
        raise UsageError("--attempts must be >= 1")
    checks = speed.all_checks()
    if args.check:
        known = {c.name: c for c in checks}
        unknown = [n for n in args.check if n not in known]
        if unknown:
            raise UsageError(f"unknown check(s) {', '.join(unknown)}; valid checks: {', '.join(known)}")
        checks = [known[n] for n in args.check]
    if args.list:
        for check in checks:
            print(f"{check.name:28s} min ratio {check.min_ratio:<7g} {check.description}")
        return 0
    if args.calibrate is not None:
        if args.calibrate < 1:
            raise UsageError("--calibrate needs N >= 1")
        entries = {}
        for check in checks:
            entries[check.name] = speed.calibrate(check, runs=args.calibrate, doubled_runs=max(1, args.calibrate // 2))
            if not args.json:
                print(f"{check.name}: {json.dumps({k: round(v, 4) for k, v in entries[check.name].items()})} "
                      f"(threshold now {check.min_ratio:g})", flush=True)
        if args.json:
            print(json.dumps(entries, indent=2))
        return 0
    outcomes = []
    for check in checks:
        outcomes.append(speed.evaluate(check, attempts=args.attempts))
        if not args.json:
            print(speed.format_outcomes(outcomes[-1:]).splitlines()[-1] if len(outcomes) > 1
                  else speed.format_outcomes(outcomes[-1:]), flush=True)
    tripped = []
    if args.trips:
        if not args.json:
            print("the same code doing its work twice (each must fail):", flush=True)
        for check in speed.trip_checks(checks):
            tripped.append(speed.trips(check))
            if not args.json:
                line = speed.format_outcomes(tripped[-1:]).splitlines()[-1]
                verdict = ("DOUBLED PASSED (the gate would miss a 2x slowdown)" if tripped[-1].passed
                           else "tripped, as it should")
                print(line[: line.rindex(" ok" if tripped[-1].passed else " TOO SLOW") + 1] + verdict, flush=True)
    if args.json:
        document: Any = [o.to_dict() for o in outcomes]
        if args.trips:
            document = {"checks": document, "doubled": [o.to_dict() for o in tripped]}
        print(json.dumps(document, indent=2))
    return 0 if all(o.passed for o in outcomes) and not any(o.passed for o in tripped) else 1


# ---------------------------------------------------------------------------------- train
def run_train(args: argparse.Namespace) -> int:
    from fkn_bench.flexkalmannet.benchmark import measure_training_speed
    from fkn_bench.flexkalmannet.config import FlexKalmanNetConfig

    if args.reference_windows is not None and args.reference_windows < 1:
        raise UsageError("--reference-windows must be >= 1")
    from fkn_bench.runtime import resolve_device

    try:
        config = FlexKalmanNetConfig(device=str(resolve_device(args.device)))
    except ValueError as error:
        raise UsageError(str(error)) from None
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
    print(f"  batched trainer       {speed.trainer_seconds_per_epoch:8.2f} s/epoch (median of {speed.trainer_epochs_timed}, "
          f"on {config.device})")
    print(f"  ratio                 {speed.ratio:8.1f}x")
    if args.time_varying:
        from fkn_bench.flexkalmannet.benchmark import time_varying_ratio

        constant, varying = time_varying_ratio(args.scenario, config, epochs=args.trainer_epochs)
        print(f"  trainer, constant     {constant:8.2f} s/epoch")
        print(f"  trainer, time-varying {varying:8.2f} s/epoch: {varying / constant:.1f}x the constant mode (timed alternately)")
    return 0
