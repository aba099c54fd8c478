"""Cost measurements: wall time per step and peak resident memory.

* Wall time: :func:`time.perf_counter` around the call. ``us_per_step_batched`` is the time of one
  ``estimate()`` call on a cell's batch divided by ``B x T`` (sequence steps), i.e. the amortised
  cost of one filter step when many sequences are filtered together; ``us_per_step_online`` is
  the time of ``reset()`` plus ``step()`` over the first :data:`~fkn_bench.harness.grid.ONLINE_STEPS`
  steps of one sequence divided by the step count: the latency of a step in a real-time loop.
* Peak memory: the growth of the process's peak resident set size (Linux ``VmHWM``) during the
  call, in MiB, after resetting the peak with ``/proc/self/clear_refs`` (Linux >= 4.0). It covers
  every allocator (numpy, torch, Python). Where that interface is missing it is NaN.

Timings and memory vary from run to run and machine to machine; they are reported but never
compared for determinism.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Measurement", "measure", "peak_rss_supported"]

_STATUS = Path("/proc/self/status")
_CLEAR_REFS = Path("/proc/self/clear_refs")


def _status_kib(field: str) -> float | None:
    try:
        for line in _STATUS.read_text().splitlines():
            if line.startswith(field + ":"):
                return float(line.split()[1])
    except OSError:
        return None
    return None


def _reset_peak() -> bool:
    try:
        _CLEAR_REFS.write_text("5")
    except OSError:
        return False
    return True


def peak_rss_supported() -> bool:
    """Whether the peak resident set size can be reset and read on this system."""
    return _status_kib("VmHWM") is not None and _reset_peak()


@dataclass
class Measurement:
    """Filled in when the :func:`measure` block ends: ``seconds`` of wall time and
    ``peak_memory_mib`` (NaN when unsupported)."""

    seconds: float = float("nan")
    peak_memory_mib: float = float("nan")


@contextmanager
def measure(*, memory: bool = True) -> Iterator[Measurement]:
    """Measure the wall time (and, with ``memory``, the peak RSS growth) of the block."""
    result = Measurement()
    baseline = None
    if memory and _reset_peak():
        baseline = _status_kib("VmRSS")
    start = time.perf_counter()
    try:
        yield result
    finally:
        result.seconds = time.perf_counter() - start
        if baseline is not None:
            peak = _status_kib("VmHWM")
            if peak is not None:
                result.peak_memory_mib = max(peak - baseline, 0.0) / 1024.0
