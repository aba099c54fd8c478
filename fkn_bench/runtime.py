"""Process-level settings for the torch parts: thread count and default dtype handling.

On small machines the filter's many small operations run fastest on one thread, and with two
threads and a busy second core a step can run ten times slower (REFERENCE.md, measured here:
20 x 1600 EKF steps took 8 s with two threads beside another process, 0.5 s with one). The
estimators therefore run the filter core under :func:`torch_threads` with ``FILTER_THREADS``
threads; set the environment variable ``FKN_BENCH_THREADS`` to change it.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

import torch

__all__ = ["FILTER_THREADS", "torch_threads"]


def _threads_from_environment() -> int:
    value = os.environ.get("FKN_BENCH_THREADS", "1")
    try:
        threads = int(value)
    except ValueError:
        raise ValueError(f"FKN_BENCH_THREADS must be a positive integer (got {value!r})") from None
    if threads < 1:
        raise ValueError(f"FKN_BENCH_THREADS must be a positive integer (got {value!r})")
    return threads


FILTER_THREADS = _threads_from_environment()


@contextmanager
def torch_threads(threads: int | None = FILTER_THREADS) -> Iterator[None]:
    """Run the block with ``threads`` intra-op torch threads (None: leave unchanged)."""
    previous = torch.get_num_threads()
    change = threads is not None and threads != previous
    if change:
        torch.set_num_threads(int(threads))  # type: ignore[arg-type]
    try:
        yield
    finally:
        if change:
            torch.set_num_threads(previous)
