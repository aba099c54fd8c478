"""Process-level settings for the torch parts: thread count, default dtype handling, and the
device batched work runs on (:func:`resolve_device`: ``--device``).

The filter core is many small matrix operations (13 x 13 per sequence and step), which a second
intra-op thread does not speed up and a busy second core slows down (``fkn_bench/DESIGN.md``,
"Performance notes"). The estimators therefore run it under :func:`torch_threads` with
``FILTER_THREADS`` threads (default 1); the environment variable ``FKN_BENCH_THREADS`` changes it.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

import torch

__all__ = ["FILTER_THREADS", "torch_threads", "parse_device", "resolve_device"]


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


def parse_device(name: str | torch.device) -> torch.device:
    """The torch device ``name`` names, whether or not this machine has it (a stored config may
    name another machine's GPU); ``ValueError`` for a name torch does not know."""
    try:
        return torch.device(name)
    except (RuntimeError, TypeError):
        raise ValueError(f"unknown device {name!r}: use cpu, cuda or cuda:N") from None


def resolve_device(name: str | torch.device) -> torch.device:
    """The torch device ``name`` (``cpu``, ``cuda``, ``cuda:1``, ``mps``) for batched filtering
    and training, checked to exist on this machine: ``ValueError`` naming the problem for a name
    torch does not know, and for an accelerator this torch build or machine lacks (a CPU-only
    build, no GPU, an index past the last GPU). The CPU is the default everywhere; nothing
    requires an accelerator."""
    device = parse_device(name)
    if device.type == "cuda":
        if not torch.cuda.is_available():
            build = "a CPU-only build" if torch.version.cuda is None else f"built for CUDA {torch.version.cuda}"
            raise ValueError(f"device {str(device)!r} asked for, but CUDA is not available here (torch "
                             f"{torch.__version__}, {build}; no usable GPU): use the CPU (--device cpu, or device = \"cpu\" in a config)")
        if device.index is not None and device.index >= torch.cuda.device_count():
            raise ValueError(f"device {str(device)!r} asked for, but this machine has {torch.cuda.device_count()} GPU(s)")
    elif device.type == "mps" and not torch.backends.mps.is_available():
        raise ValueError(f"device {str(device)!r} asked for, but MPS is not available here: use the CPU (--device cpu)")
    elif device.type not in ("cpu", "cuda", "mps"):
        raise ValueError(f"device {str(device)!r} is not supported: use cpu, cuda or cuda:N")
    return device
