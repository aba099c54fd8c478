"""Suite-wide hooks.

Timed tests and the two pytest-xdist workers: the default run (``-n 2`` in ``pyproject.toml``)
keeps both cores busy, but the speed-ratio gate compares numpy and torch code whose relative
speed changes when the other core is loaded (measured: a doubled ``online-step:manual-mekf``
passed its threshold with the other worker running the suite). A test marked ``exclusive_cpu``
therefore holds an exclusive lock for its whole run (setup, call, teardown) and every other test
a shared one, fixtures of wider scope included (they are built inside the setup of the first test
that needs them): while a timed test runs, the other worker waits between its tests, and the
timing sees the machine the thresholds were calibrated on. Keep the ``exclusive_cpu`` tests in
``tests/gates/test_speed_gate.py``: xdist's ``loadfile`` hands out the files with the most tests
first, so they run at the start, beside short tests; one in another file ran beside the
accuracy gate's 70-second fixture and left its worker idle that long. Without xdist (``-n 0``), or where
``fcntl`` does not exist (Windows), no lock is taken.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from pathlib import Path

import pytest

try:
    import fcntl
except ImportError:  # not a POSIX system: run without the lock
    fcntl = None  # type: ignore[assignment]


def _lock_path() -> Path | None:
    if fcntl is None or not os.environ.get("PYTEST_XDIST_WORKER"):
        return None
    # one fixed file: the workers of one run share it (so would two runs at once, which is right:
    # they share the cores too); flock locks end with their process, so a stale file is harmless
    return Path(tempfile.gettempdir()) / "fkn-bench-exclusive-cpu.lock"


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    """Shared lock around an ordinary test, exclusive around an ``exclusive_cpu`` one."""
    path = _lock_path()
    if path is None:
        yield
        return
    exclusive = item.get_closest_marker("exclusive_cpu") is not None
    with open(path, "a+") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


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
