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
    """Under pytest-xdist, the test files that hold a test marked ``slow`` (a session- or
    module-scoped fixture of 10 s and more, or tests of as much together) go first, in their
    collection order, and the other files after them: ``--dist loadfile`` hands out whole files in
    the order collected (``--no-loadscope-reorder`` in ``pyproject.toml``), so the long files
    start while the short ones are left to even out the two workers' ends, instead of a long file
    starting last on one worker while the other idles. Without xdist the order is left alone."""
    if not hasattr(config, "workerinput"):  # not an xdist worker
        return
    slow_files = {item.path for item in items if item.get_closest_marker("slow")}
    items.sort(key=lambda item: item.path not in slow_files)  # stable: the order within each group is kept


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
