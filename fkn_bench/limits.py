"""Size limits: work that would exceed the machine's memory is refused before it allocates.

A scenario with ``n_steps = 100_000_000_000``, a recording whose stamps jump by 1e6 s (resampled
to ten million steps), or a thousand seeds of ds1 at once would otherwise run for minutes and end
in a ``MemoryError`` traceback, or take the machine down with it. Every place that allocates in
proportion to steps x sequences checks the estimate first with :func:`check_memory`, which raises
:class:`SizeLimitError` (a ``ValueError``) naming what was asked, what it would take, the limit,
and how to raise it.

The limit is :func:`memory_limit_bytes`: the ``FKN_BENCH_MEMORY_LIMIT_GB`` environment variable
when set (GiB, e.g. ``FKN_BENCH_MEMORY_LIMIT_GB=64``), else half of the machine's physical memory
(the rest is for the interpreter, torch and the other worker).
"""

from __future__ import annotations

import os

__all__ = ["SizeLimitError", "check_memory", "memory_limit_bytes", "MEMORY_LIMIT_VARIABLE", "GIB",
           "ESTIMATION_BYTES_PER_STEP"]

MEMORY_LIMIT_VARIABLE = "FKN_BENCH_MEMORY_LIMIT_GB"
GIB = 1024**3


ESTIMATION_BYTES_PER_STEP = 8000
"""Memory one step of one sequence takes while an estimator filters it and the harness scores it:
the Kalman filters keep means, 13x13 and 12x12 covariances and innovations of every step
(6.0-6.5 kB per step measured as peak RSS growth for manual-ekf, sage-husa and
rigid-body-ukf-ratios on 10 x 8000 steps; KalmanNet, without covariances, 0.5 kB)."""


class SizeLimitError(ValueError):
    """Work refused before allocation because it would need more memory than the limit."""


def physical_memory_bytes() -> int | None:
    """The machine's physical memory in bytes (None where the platform does not say)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


def memory_limit_bytes() -> int:
    """The memory limit in bytes (module docstring); a malformed variable raises
    :class:`SizeLimitError` naming it."""
    text = os.environ.get(MEMORY_LIMIT_VARIABLE)
    if text is not None:
        try:
            gigabytes = float(text)
        except ValueError:
            gigabytes = float("nan")
        if not gigabytes > 0 or gigabytes == float("inf"):
            raise SizeLimitError(f"{MEMORY_LIMIT_VARIABLE} must be a positive number of GiB (got {text!r})")
        return int(gigabytes * GIB)
    physical = physical_memory_bytes()
    return physical // 2 if physical else 8 * GIB


def check_memory(nbytes: float, what: str, smaller: str) -> None:
    """Raise :class:`SizeLimitError` when ``nbytes`` (an estimate) exceeds the limit: ``what``
    names the work ("ds1 with n_steps = 1e11 for 10 seeds"), ``smaller`` how to ask for less
    ("fewer steps or seeds")."""
    limit = memory_limit_bytes()
    if nbytes > limit:
        source = f"{MEMORY_LIMIT_VARIABLE}" if MEMORY_LIMIT_VARIABLE in os.environ else \
            f"half of this machine's memory; set {MEMORY_LIMIT_VARIABLE}=<GiB> to raise it"
        raise SizeLimitError(
            f"{what} would need about {nbytes / GIB:.3g} GiB of memory, over the limit of "
            f"{limit / GIB:.3g} GiB ({source}); ask for {smaller}"
        )
