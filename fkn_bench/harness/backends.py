"""Execution backends: where grid cells run.

Every backend runs :func:`fkn_bench.harness.cell.run_cell` on each cell and yields the results as
they complete; the caller (the runner, in the client process) writes them. Cells are independent
and each is computed identically wherever it runs (fixed seed chunks, one torch thread), so all
backends give bit-identical metrics for the same cells.
"""

from __future__ import annotations

import concurrent.futures
import multiprocessing
from collections.abc import Iterator, Sequence
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:  # (imported where cells run: listing BACKENDS must not import torch)
    from fkn_bench.harness.grid import CellSpec
    from fkn_bench.harness.records import CellRecord

__all__ = ["Backend", "LocalBackend", "DaskBackend", "make_backend", "BACKENDS"]

BACKENDS: tuple[str, ...] = ("local", "dask")


class Backend(Protocol):
    """Runs cells and yields their results in completion order."""

    name: str

    def run(self, cells: Sequence[CellSpec]) -> Iterator[CellRecord]: ...


class LocalBackend:
    """This process (``workers == 1``) or a pool of spawned processes."""

    name = "local"

    def __init__(self, workers: int = 1) -> None:
        if workers < 1:
            raise ValueError(f"workers must be >= 1 (got {workers})")
        self.workers = int(workers)

    def run(self, cells: Sequence[CellSpec]) -> Iterator[CellRecord]:
        from fkn_bench.harness.cell import run_cell

        if self.workers == 1 or len(cells) <= 1:
            for cell in cells:
                yield run_cell(cell)
            return
        from fkn_bench.wording import worker_initializer

        context = multiprocessing.get_context("spawn")  # no forked torch state
        initializer, initargs = worker_initializer()  # the command line's one-line warnings
        with concurrent.futures.ProcessPoolExecutor(max_workers=self.workers, mp_context=context,
                                                    initializer=initializer, initargs=initargs) as pool:
            futures = [pool.submit(run_cell, cell) for cell in cells]
            try:
                for future in concurrent.futures.as_completed(futures):
                    yield future.result()
            finally:
                for future in futures:
                    future.cancel()


class DaskBackend:
    """A Dask distributed cluster at ``scheduler`` (``tcp://host:8786``), or a ``LocalCluster`` of
    ``workers`` single-threaded processes started for the run. Workers need fkn-bench installed;
    they return results to the client, so they need not share a file system with it."""

    name = "dask"

    def __init__(self, scheduler: str | None = None, workers: int = 1) -> None:
        if workers < 1:
            raise ValueError(f"workers must be >= 1 (got {workers})")
        self.scheduler = scheduler
        self.workers = int(workers)

    def run(self, cells: Sequence[CellSpec]) -> Iterator[CellRecord]:
        import logging

        from distributed import Client, LocalCluster, as_completed

        from fkn_bench.harness.cell import run_cell

        cluster = None
        if self.scheduler is None:
            cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                   dashboard_address=":0", silence_logs=logging.ERROR)
        client = Client(cluster if cluster is not None else self.scheduler)
        try:
            futures = [client.submit(run_cell, cell, pure=False) for cell in cells]
            try:
                for future in as_completed(futures):
                    yield future.result()
            finally:
                client.cancel(futures)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()


def make_backend(name: str, *, workers: int = 1, scheduler: str | None = None) -> Backend:
    """Backend by name (:data:`BACKENDS`)."""
    if name == "local":
        if scheduler is not None:
            raise ValueError("--scheduler needs --backend dask")
        return LocalBackend(workers)
    if name == "dask":
        return DaskBackend(scheduler, workers)
    raise ValueError(f"unknown backend {name!r}; valid backends: {', '.join(BACKENDS)}")
