"""fkn_bench.runtime: the torch thread count is set for a block and restored; a device is checked
to exist before batched work is put on it."""

from __future__ import annotations

import importlib

import pytest
import torch

from fkn_bench import runtime


@pytest.fixture(autouse=True)
def restore_threads():  # noqa: ANN201
    previous = torch.get_num_threads()
    yield
    torch.set_num_threads(previous)


def test_torch_threads_sets_and_restores() -> None:
    torch.set_num_threads(2)
    with runtime.torch_threads(1):
        assert torch.get_num_threads() == 1
    assert torch.get_num_threads() == 2
    with runtime.torch_threads(None):
        assert torch.get_num_threads() == 2
    with runtime.torch_threads(2):
        assert torch.get_num_threads() == 2
    assert torch.get_num_threads() == 2


def test_torch_threads_restores_after_an_exception() -> None:
    torch.set_num_threads(2)
    with pytest.raises(RuntimeError, match="boom"):
        with runtime.torch_threads(1):
            assert torch.get_num_threads() == 1
            raise RuntimeError("boom")
    assert torch.get_num_threads() == 2


def test_nested_blocks() -> None:
    torch.set_num_threads(2)
    with runtime.torch_threads(1):
        with runtime.torch_threads(3):
            assert torch.get_num_threads() == 3
        assert torch.get_num_threads() == 1
    assert torch.get_num_threads() == 2


def test_default_comes_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    try:
        monkeypatch.setenv("FKN_BENCH_THREADS", "3")
        assert importlib.reload(runtime).FILTER_THREADS == 3
        torch.set_num_threads(1)
        with runtime.torch_threads():
            assert torch.get_num_threads() == 3
        for bad in ("zero", "0", "-2", "1.5"):
            monkeypatch.setenv("FKN_BENCH_THREADS", bad)
            with pytest.raises(ValueError, match="FKN_BENCH_THREADS must be a positive integer"):
                importlib.reload(runtime)
        monkeypatch.delenv("FKN_BENCH_THREADS")
        assert importlib.reload(runtime).FILTER_THREADS == 1
    finally:
        monkeypatch.undo()
        importlib.reload(runtime)


def test_resolve_device_names_what_is_wrong() -> None:
    assert runtime.resolve_device("cpu") == torch.device("cpu")
    for name, message in (("gpu", "unknown device 'gpu': use cpu, cuda or cuda:N"),
                          ("meta", "device 'meta' is not supported"),
                          ("cuda:7", "device 'cuda:7' asked for, but ")):
        with pytest.raises(ValueError, match=message):
            runtime.resolve_device(name)
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="CUDA is not available here"):
            runtime.resolve_device("cuda")
