"""pyproject.toml ships every package of the source tree (an editable install hides a missing
entry; a wheel would lack the package)."""

from __future__ import annotations

import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
MAPPED = {"fkn_bench.envs": "envs", "fkn_bench.baselines": "baselines"}


def test_every_package_directory_is_listed_in_pyproject() -> None:
    config = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(config["packages"])
    present = {".".join(p.parent.relative_to(REPO).parts) for p in (REPO / "fkn_bench").rglob("__init__.py")}
    present |= {name for name, directory in MAPPED.items() if (REPO / directory / "__init__.py").is_file()}
    assert present - listed == set(), f"packages missing from pyproject.toml's [tool.setuptools] packages: {sorted(present - listed)}"
    assert listed - present == set(), f"pyproject.toml lists packages that do not exist: {sorted(listed - present)}"
    assert config["package-dir"].items() >= MAPPED.items()


def test_every_data_file_of_a_package_is_shipped() -> None:
    """The committed parameter files (``<package>/params/``) and the sweep spaces are package data:
    a file that no ``package-data`` pattern of its package matches would be missing from a wheel."""
    config = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    directories = {**{name: REPO / Path(*name.split(".")) for name in config["packages"]}, **{n: REPO / d for n, d in MAPPED.items()}}
    for package, directory in directories.items():
        for folder in ("params", "spaces"):
            for path in sorted(p for p in (directory / folder).rglob("*") if p.is_file() and "__pycache__" not in p.parts):
                patterns = config["package-data"].get(package, [])
                assert any(path.relative_to(directory).match(p) for p in patterns), \
                    f"{path.relative_to(REPO)} is not shipped: add a pattern to pyproject.toml [tool.setuptools.package-data] {package!r}"
