"""Provenance of results: package version, git commit, library versions and machine.

Recorded in every cell's JSON, each results directory, trained artefacts and MCAP recordings, so a
number can always be traced to the code and machine that produced it. A ground-floor module: it
imports nothing of fkn-bench but the package version.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from functools import lru_cache
from pathlib import Path
from typing import Any

__all__ = ["environment", "git_commit"]


def git_commit(path: str | Path | None = None) -> str | None:
    """The git commit of the source tree at ``path`` (default: this package), with ``-dirty``
    appended when tracked files have uncommitted changes; None outside a git checkout."""
    where = Path(path) if path is not None else Path(__file__).resolve().parent
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=where, capture_output=True, text=True, timeout=10, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=where,
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return f"{commit}-dirty" if dirty else commit or None


def _version(module: str) -> str | None:
    try:
        return str(__import__(module).__version__)
    except Exception:  # noqa: BLE001 - missing or odd module: record None
        return None


def _cpu_model() -> str | None:
    """The CPU's model name (Linux ``/proc/cpuinfo``; None elsewhere): results that are equal only
    to rounding differ between CPU vendors (BLAS and SIMD code paths), so provenance names it."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip() or None
    except OSError:
        pass
    return None


@lru_cache(maxsize=1)
def environment() -> dict[str, Any]:
    """Versions and machine description of this process (cached)."""
    from fkn_bench import __version__

    return {
        "fkn_bench": __version__,
        "git_commit": git_commit(),
        "python": platform.python_version(),
        "numpy": _version("numpy"),
        "torch": _version("torch"),
        "scipy": _version("scipy"),
        "pandas": _version("pandas"),
        "machine": {
            "platform": platform.platform(),
            "machine": platform.machine(),
            "processor": platform.processor() or _cpu_model(),
            "cpu_count": os.cpu_count(),
            "implementation": sys.implementation.name,
        },
    }
