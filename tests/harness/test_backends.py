"""The process-pool and Dask backends give the local backend's metrics bit for bit."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from fkn_bench.harness import DaskBackend, LocalBackend, build_grid, deterministic_rows, make_backend, run_grid
from fkn_bench.harness.sources import SimulatedSource


@pytest.fixture(scope="module")
def grid(short_ds1: SimulatedSource):
    return build_grid(["manual-ekf", "manual-mekf"], [short_ds1], range(12))  # 4 cells, two seed chunks


@pytest.fixture(scope="module")
def local(grid):
    return run_grid(grid, backend=LocalBackend(1), progress=False).results


def _assert_identical(a, b) -> None:
    # exact: the same cells computed in worker processes of this machine (same wheels, the filter's
    # torch thread count fixed by runtime.torch_threads): the same computation, only elsewhere
    pd.testing.assert_frame_equal(deterministic_rows(a.rows), deterministic_rows(b.rows), check_exact=True)
    for estimator, scenario in a.pairs():
        for x, y in zip(a.pooled(estimator, scenario), b.pooled(estimator, scenario)):
            assert np.array_equal(x.sum, y.sum) and np.array_equal(x.count, y.count)


@pytest.mark.slow
def test_dask_local_cluster_matches_local(grid, local) -> None:
    # one worker process: the cells still run elsewhere and come back through Dask (the process
    # pool's test below covers results arriving out of order from two workers)
    results = run_grid(grid, backend=DaskBackend(workers=1), progress=False).results
    _assert_identical(local, results)


@pytest.mark.slow
def test_process_pool_matches_local(grid, local) -> None:
    results = run_grid(grid, backend=LocalBackend(workers=2), progress=False).results
    _assert_identical(local, results)


def test_make_backend() -> None:
    assert make_backend("local").name == "local"
    assert make_backend("dask", workers=3).workers == 3
    with pytest.raises(ValueError, match="--scheduler"):
        make_backend("local", scheduler="tcp://x:1")
    with pytest.raises(ValueError, match="valid backends"):
        make_backend("ray")
    with pytest.raises(ValueError):
        LocalBackend(0)
