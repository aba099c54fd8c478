"""Shared fixtures of the speed suite (``tests/benchmarks``; not part of the default test run).

Run it with ``python -m pytest tests/benchmarks -n 0 --benchmark-only --benchmark-json=bench.json`` (``-n 0``:
one process; pytest-benchmark switches itself off under the default run's xdist workers)
and summarise with ``fkn-bench bench report bench.json`` (or both: ``fkn-bench bench run``).
Every benchmark records in ``extra_info`` how many ``steps`` (environment, filter or scored time
steps) one timed call processes, so the report can print throughputs; timings run on one torch
thread, as the estimators do (:mod:`fkn_bench.runtime`).

Two environment variables (``fkn-bench bench run --device D --large-batch N`` sets them) move the
batched filter and training benchmarks to an accelerator: ``FKN_BENCH_DEVICE`` (``cpu``, the
default, or ``cuda``) and ``FKN_BENCH_LARGE_BATCH`` (the large batch, 1024 by default; the
benchmarks keep their ``batch_1024`` names): :func:`fkn_bench.gates.speed.suite_device` and
:func:`~fkn_bench.gates.speed.suite_large_batch`. On a GPU each timed call ends with a
synchronisation (:func:`fkn_bench.gates.speed.synchronized`), so it times the work, not its launch.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from fkn_bench.runtime import torch_threads


@pytest.fixture(autouse=True)
def _one_torch_thread() -> Iterator[None]:
    with torch_threads():
        yield

