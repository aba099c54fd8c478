"""Shared fixtures of the speed suite (``tests/benchmarks``; not part of the default test run).

Run it with ``python -m pytest tests/benchmarks -n 0 --benchmark-only --benchmark-json=bench.json`` (``-n 0``:
one process; pytest-benchmark switches itself off under the default run's xdist workers)
and summarise with ``fkn-bench bench report bench.json`` (or both: ``fkn-bench bench run``).
Every benchmark records in ``extra_info`` how many ``steps`` (environment, filter or scored time
steps) one timed call processes, so the report can print throughputs; timings run on one torch
thread, as the estimators do (:mod:`fkn_bench.runtime`).
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from fkn_bench.runtime import torch_threads


@pytest.fixture(autouse=True)
def _one_torch_thread() -> Iterator[None]:
    with torch_threads():
        yield

