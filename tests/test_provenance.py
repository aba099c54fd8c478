"""Provenance: the environment record names versions and machine; git_commit reads a checkout."""

from __future__ import annotations

from pathlib import Path

from fkn_bench import __version__
from fkn_bench.provenance import environment, git_commit


def test_environment_names_versions_and_machine() -> None:
    env = environment()
    assert env["fkn_bench"] == __version__
    assert {"python", "numpy", "torch", "git_commit", "machine"} <= set(env)
    assert {"platform", "machine", "cpu_count"} <= set(env["machine"])
    assert environment() is env  # cached


def test_git_commit_outside_a_checkout_is_none(tmp_path: Path) -> None:
    assert git_commit(tmp_path) is None
    commit = git_commit()
    assert commit is None or len(commit.removesuffix("-dirty")) == 40
