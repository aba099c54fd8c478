"""Suite-wide fixtures: one torch thread, the scenario registry restored after each test and
module, the GPU's filter path on the CPU, torch's ``meta`` default device, and simulated kills;
and the order in which pytest-xdist hands out the test files (the files that hold a test marked
``slow`` first).

No test here times anything: the speed-ratio gate's timed checks run after the tests as
``fkn-bench bench gate --trips`` (README, "Benchmarks and CI gates"), where no second pytest
worker shares the machine.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager

import pytest


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Under pytest-xdist, the test files that hold a test marked ``slow`` go first, the longest
    first (by the largest ``seconds`` their ``slow`` markers give; 10 where none is given), and
    the other files after them in their collection order. ``--dist loadfile`` hands out whole files
    in the order collected (``--no-loadscope-reorder`` in ``pyproject.toml``), the first two to
    the two workers: the long files start at once on both workers, and the short ones even out
    the two workers' ends (a long file handed out last keeps one worker busy while the other
    idles). Without xdist the order is left alone."""
    if not hasattr(config, "workerinput"):  # not an xdist worker
        return
    seconds: dict[object, float] = {}
    for item in items:
        marks = [mark.kwargs.get("seconds", 10.0) for mark in item.iter_markers("slow")]
        seconds[item.path] = max([seconds.get(item.path, 0.0), *marks])
    items.sort(key=lambda item: -seconds[item.path])  # stable: each file's tests keep their order


@pytest.fixture(autouse=True, scope="session")
def _one_torch_thread() -> Iterator[None]:
    """One intra-op torch thread in each test process (restored at the end): the test command runs
    two pytest-xdist workers on two cores, and with two threads each, a torch operation waits for
    a thread that the other worker's core holds (the filter runs at one thread everywhere:
    :mod:`fkn_bench.runtime`). A test that needs another count sets it and restores it."""
    import torch

    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)


def _restoring_the_scenario_registry() -> Iterator[None]:
    from fkn_bench.scenarios import registry

    saved = dict(registry._REGISTRY)
    yield
    registry._REGISTRY.clear()
    registry._REGISTRY.update(saved)


@pytest.fixture(autouse=True, scope="module")
def _scenario_registry_restored_after_the_module() -> Iterator[None]:
    """Scenarios a test file registers (a TOML file it loads, a sweep it runs; in a fixture of any
    scope) are gone after it, so that no later file on the same xdist worker sees them in
    ``scenario_names()``."""
    yield from _restoring_the_scenario_registry()


@pytest.fixture(autouse=True)
def _scenario_registry_restored_after_the_test() -> Iterator[None]:
    """The same after each test, for the tests of a file that follow it."""
    yield from _restoring_the_scenario_registry()


@pytest.fixture
def gpu_path(monkeypatch: pytest.MonkeyPatch) -> None:
    """The filter step a GPU runs, on the CPU: no compiled CPU kernels
    (:mod:`fkn_bench.filters.kernels`), the structured EKF step at any batch."""
    from fkn_bench.filters import ekf, kernels

    monkeypatch.setattr(kernels, "ENABLED", False)
    monkeypatch.setattr(ekf, "STRUCTURED_MIN_BATCH", 1)


@pytest.fixture
def meta_default_device() -> Callable[[], AbstractContextManager[None]]:
    """``with meta_default_device(): ...`` runs the block with torch's default device ``meta``
    (restored after): a tensor made there without following its inputs' device lands on ``meta``
    and fails against the CPU inputs, as it would land on the CPU beside a GPU's inputs
    (``tests/filters/test_device.py``)."""
    import torch

    @contextmanager
    def block() -> Iterator[None]:
        torch.set_default_device("meta")
        try:
            yield
        finally:
            torch.set_default_device(None)

    return block


class SimulatedKill(BaseException):
    """Raised by :func:`kill_at_write` in place of a SIGKILL (a ``BaseException``: no
    ``except Exception`` of the code under test catches it)."""


@pytest.fixture
def kill_at_write(monkeypatch: pytest.MonkeyPatch) -> Callable[[int], AbstractContextManager[list[str]]]:
    """``with kill_at_write(n) as written: ...`` lets the first ``n - 1`` renames
    (``os.replace``: every atomic write of :mod:`fkn_bench.io` ends with one) through and "kills"
    the process at the ``n``-th, as SIGKILL would between
    writing a file's temporary copy and renaming it over the target: the target is not replaced,
    a stray temporary file is left beside it, and :class:`SimulatedKill` propagates (caught by the
    block; ``written`` lists the targets replaced before the kill). A block that makes fewer than
    ``n`` writes finishes normally. Resume tests run a command once per kill point and compare
    the resumed result with the uninterrupted one."""
    import shutil

    from fkn_bench import io

    real_replace = io.os.replace

    @contextmanager
    def block(n: int) -> Iterator[list[str]]:
        written: list[str] = []

        def replace(src: str | os.PathLike[str], dst: str | os.PathLike[str]) -> None:
            if len(written) + 1 == n:
                shutil.copyfile(src, f"{src}.killed.tmp")  # what a real kill leaves behind
                raise SimulatedKill(f"killed before writing {dst}")
            real_replace(src, dst)
            written.append(str(dst))

        monkeypatch.setattr(io.os, "replace", replace)
        try:
            yield written
        except SimulatedKill:
            pass
        finally:
            monkeypatch.setattr(io.os, "replace", real_replace)

    return block
