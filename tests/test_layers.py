"""Layer rules: imports point down only, and no module sits in an import cycle.

The layers are the table of ``fkn_bench/DESIGN.md`` ("Layers"), read here (:data:`LAYERS`); that
file also states which imports count. Every module of ``fkn_bench`` is parsed (``ast``, nothing
is imported), the mapped packages included (``fkn_bench.envs`` = ``envs/``,
``fkn_bench.baselines`` = ``baselines/``). A module imports another (:func:`_imports`) by

* an ``import`` statement anywhere: module level, inside functions, under ``if TYPE_CHECKING``;
* a string: ``importlib.import_module("fkn_bench....")`` (an f-string by its constant prefix), a
  value of a lazy export map passed to ``lazy_exports`` (``".sub"`` relative to the package, or
  ``"fkn_bench...."``), a ``"fkn_bench.mod:attribute"`` reference;
* a resource: ``importlib.resources.files("fkn_bench....")``;
* an entry point (:func:`_entry_point_edges`): a module named in ``pyproject.toml``'s
  ``[project.entry-points."G"]`` imports the registry that owns group ``G`` (the module that sets
  ``ENTRY_POINT_GROUP = "G"``).

The layer rule counts them all. The cycle rule counts the imports that run when a module is
imported: module level, outside ``if TYPE_CHECKING``. An import ``from a.b import c`` is an edge to
``a.b.c`` when that is a module, else to ``a.b`` (not to the parent packages, which Python
initialises first anyway).
"""

from __future__ import annotations

import ast
import bisect
import re
import tomllib
from collections.abc import Iterator, Mapping
from functools import lru_cache
from pathlib import Path
from typing import Any, NamedTuple

import pytest

REPO = Path(__file__).resolve().parents[1]
DESIGN = REPO / "fkn_bench" / "DESIGN.md"
PYPROJECT = REPO / "pyproject.toml"
PACKAGE_DIRS = {"fkn_bench": REPO / "fkn_bench", "fkn_bench.envs": REPO / "envs", "fkn_bench.baselines": REPO / "baselines"}

_PACKAGE_NAME = re.compile(r"`(fkn_bench(?:\.[A-Za-z_]\w*)*)`")


def layers_from_design(text: str) -> tuple[tuple[str, ...], ...]:
    """The packages of each layer, bottom first, from the table of section "## Layers" of
    DESIGN.md: rows ``| <layer number> | `fkn_bench.x` | what it holds |`` (names below
    ``fkn_bench``; "" is the package root)."""
    match = re.search(r"^## Layers[ \t]*\n(.*?)(?=^## |\Z)", text, re.M | re.S)
    section = match.group(1) if match else ""
    layers: dict[int, list[str]] = {}
    for line in section.splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        if not line.lstrip().startswith("|") or len(cells) < 3 or not cells[0].isdigit():
            continue
        names = _PACKAGE_NAME.findall(cells[1])
        assert names, f"DESIGN.md: a layer row without a `fkn_bench...` package: {line!r}"
        layers.setdefault(int(cells[0]), []).extend(n.removeprefix("fkn_bench").removeprefix(".") for n in names)
    assert layers, "DESIGN.md has no layer table under '## Layers'"
    assert sorted(layers) == list(range(len(layers))), f"DESIGN.md: layers must be numbered 0, 1, 2, ... (got {sorted(layers)})"
    packages = [p for layer in layers.values() for p in layer]
    assert len(packages) == len(set(packages)), f"DESIGN.md: a package in two rows: {sorted(p for p in packages if packages.count(p) > 1)}"
    return tuple(tuple(layers[i]) for i in range(len(layers)))


LAYERS: tuple[tuple[str, ...], ...] = layers_from_design(DESIGN.read_text(encoding="utf-8"))
"""Packages (names below ``fkn_bench``; "" is the package root), bottom layer first."""

ALLOWED: dict[tuple[str, str], str] = {
    ("fkn_bench", "fkn_bench.envs.registration"):
        "the package root registers AstrobeeTumble-v0 with Gymnasium on import (the Gymnasium convention), "
        "so that gym.make works after `import fkn_bench`",
}
"""Upward imports that are the design, ``{(module, imported module): why}``."""

KNOWN_VIOLATIONS: set[tuple[str, str]] = set()
"""``(module, imported module)`` pairs that break the layer rule today and are being fixed in
other work; remove each entry when its fix is merged (the test fails on an entry that no longer
occurs, so the list cannot go stale)."""


def _modules() -> dict[str, Path]:
    modules = {}
    for package, root in PACKAGE_DIRS.items():
        for path in sorted(root.rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            name = ".".join([package, *parts])
            if package == "fkn_bench" and parts and parts[0] in ("envs", "baselines"):
                continue  # not shipped: the mapped directories are the packages
            modules[name] = path
    return modules


MODULES = _modules()


class Import(NamedTuple):
    target: str
    line: int
    eager: bool
    kind: str  # "import", "string", "lazy map", "resource"


def _is_package(name: str) -> bool:
    return MODULES[name].name == "__init__.py"


@lru_cache(maxsize=None)
def _parse(path: Path) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


def _dotted(node: ast.AST) -> str:
    """``importlib.resources.files`` for that attribute chain, "" for anything else."""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        inner = _dotted(node.value)
        return f"{inner}.{node.attr}" if inner else ""
    return ""


def _string(node: ast.AST | None) -> str | None:
    """A constant string, or the constant prefix of an f-string (up to its last dot when a
    placeholder follows: ``f"fkn_bench.cli.{name}"`` -> ``fkn_bench.cli``)."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.JoinedStr):
        prefix = ""
        for part in node.values:
            if not (isinstance(part, ast.Constant) and isinstance(part.value, str)):
                return prefix.rpartition(".")[0] or None
            prefix += part.value
        return prefix
    return None


def _resolve(reference: str, base: str) -> str:
    """Absolute module name of ``reference`` (``".sub"`` and ``"..sub"`` relative to package
    ``base``, as ``importlib.import_module(reference, base)`` reads it)."""
    if not reference.startswith("."):
        return reference
    level = len(reference) - len(reference.lstrip("."))
    anchor = base.rsplit(".", level - 1)[0] if level > 1 else base
    rest = reference[level:]
    return f"{anchor}.{rest}" if rest else anchor


_MAY_IMPORT = re.compile(r"import_module|files|lazy_exports|fkn_bench\.")
"""What a line with an import by string or by resource contains (expressions elsewhere are skipped)."""


@lru_cache(maxsize=None)
def _references(path: Path, base: str) -> tuple[Import, ...]:
    """Every import in the module at ``path`` (package ``base``); ``target`` is the absolute name
    as written, before it is mapped to a module of the package. ``eager``: the statement runs when
    the module is imported (not inside a function or lambda, not under ``if TYPE_CHECKING``; a
    lazy map never). Expressions are searched only where their lines may hold a string import."""
    tree = _parse(path)
    marked = [n for n, text in enumerate(path.read_text(encoding="utf-8").splitlines(), 1) if _MAY_IMPORT.search(text)]
    assigned = {t.id: node.value for node in tree.body if isinstance(node, (ast.Assign, ast.AnnAssign))
                for t in (node.targets if isinstance(node, ast.Assign) else [node.target]) if isinstance(t, ast.Name)}
    found: list[Import] = []
    calls: list[tuple[ast.Call, bool]] = []
    resource_names = set()

    def statement(node: ast.AST, eager: bool) -> None:
        if isinstance(node, ast.Import):
            found.extend(Import(alias.name, node.lineno, eager, "import") for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            module = _resolve("." * node.level + (node.module or ""), base) if node.level else node.module or ""
            found.extend(Import(f"{module}.{alias.name}", node.lineno, eager, "import") for alias in node.names)
            if module == "importlib.resources":
                resource_names.update(a.asname or a.name for a in node.names if a.name == "files")
        elif isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for child in node.body:
                statement(child, False)
            for child in node.orelse:
                statement(child, eager)
        else:
            body_eager = eager and not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            for child in ast.iter_child_nodes(node):
                if isinstance(child, (ast.stmt, ast.excepthandler, ast.match_case)):
                    statement(child, body_eager)
                else:
                    expression(child, eager)

    def expression(node: ast.AST, eager: bool) -> None:
        first = getattr(node, "lineno", None)
        if first is not None:
            index = bisect.bisect_left(marked, first)
            if index == len(marked) or marked[index] > node.end_lineno:
                return
        if isinstance(node, ast.Call):
            calls.append((node, eager))
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            module, colon, attribute = node.value.partition(":")
            if colon and module.startswith("fkn_bench.") and re.fullmatch(r"[\w.]+", module + attribute):
                found.append(Import(module, node.lineno, False, "string"))
        inner = eager and not isinstance(node, ast.Lambda)
        for child in ast.iter_child_nodes(node):
            expression(child, inner)

    for node in tree.body:
        statement(node, True)
    for call, eager in calls:
        function = _dotted(call.func)
        first = call.args[0] if call.args else None
        if function.rpartition(".")[2] == "import_module" and (name := _string(first)):
            found.append(Import(_resolve(name, base), call.lineno, eager, "string"))
        elif (function.endswith("resources.files") or function in resource_names) and (name := _string(first)):
            found.append(Import(name, call.lineno, eager, "resource"))
        elif function.rpartition(".")[2] == "lazy_exports":
            exports = call.args[1] if len(call.args) > 1 else next((k.value for k in call.keywords if k.arg == "exports"), None)
            if isinstance(exports, ast.Name):
                exports = assigned.get(exports.id)
            if isinstance(exports, ast.Dict):
                for value in exports.values:
                    name = _string(value)
                    if name and name.startswith((".", "fkn_bench.")):
                        found.append(Import(_resolve(name, base), value.lineno, False, "lazy map"))
    return tuple(found)


def _imports(name: str) -> Iterator[Import]:
    """Every import of ``name`` that names a module of the package (see module docstring)."""
    base = name if _is_package(name) else name.rpartition(".")[0]
    seen = set()
    for imported in _references(MODULES[name], base):
        target = imported.target
        while target and target not in MODULES and "." in target:
            target = target.rpartition(".")[0]
        if target in MODULES and (target, imported.line, imported.kind) not in seen:
            seen.add((target, imported.line, imported.kind))
            yield imported._replace(target=target)


def _registries() -> dict[str, str]:
    """``{entry-point group: module that owns it}`` (``ENTRY_POINT_GROUP = "..."`` at module level)."""
    owners = {}
    for module, path in MODULES.items():
        for node in _parse(path).body:
            if (isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "ENTRY_POINT_GROUP" for t in node.targets)
                    and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str)):
                owners[node.value.value] = module
    return owners


def _entry_point_edges(pyproject: Mapping[str, Any], registries: Mapping[str, str]) -> list[tuple[str, str, str]]:
    """``(entry module, registry module, "pyproject.toml [group] name")`` for every entry point of
    a group that a module of the package owns."""
    edges = []
    for group, entries in pyproject.get("project", {}).get("entry-points", {}).items():
        if group not in registries:
            continue
        for entry, reference in entries.items():
            module = reference.partition(":")[0].strip()
            assert module in MODULES, f"pyproject.toml [project.entry-points.{group!r}] {entry} names {module!r}, not a module of fkn_bench"
            edges.append((module, registries[group], f"pyproject.toml [project.entry-points.\"{group}\"] {entry}"))
    return edges


def _pyproject() -> dict[str, Any]:
    return tomllib.loads(PYPROJECT.read_text(encoding="utf-8"))


@lru_cache(maxsize=None)
def layer_of(module: str) -> int:
    """Index in :data:`LAYERS` of ``module`` (the longest matching package wins)."""
    relative = module.removeprefix("fkn_bench").removeprefix(".")
    best, depth = None, -1
    for index, packages in enumerate(LAYERS):
        for package in packages:
            if package == "" and depth < 0:
                best, depth = index, 0
            elif package and (relative == package or relative.startswith(package + ".")) and package.count(".") + 1 > depth:
                best, depth = index, package.count(".") + 1
    assert best is not None, f"{module} is in no layer: add its package to the table of fkn_bench/DESIGN.md"
    return best


def _layer_violations(pyproject: Mapping[str, Any] | None = None) -> list[tuple[str, str, str]]:
    """``(module, imported module, where)`` for every import that points up."""
    found = []
    for module in MODULES:
        for imported in _imports(module):
            if layer_of(imported.target) > layer_of(module) and (module, imported.target) not in ALLOWED:
                where = f"{MODULES[module].relative_to(REPO) if MODULES[module].is_relative_to(REPO) else MODULES[module]}:{imported.line}"
                found.append((module, imported.target, f"{where} ({imported.kind})"))
    for module, registry, where in _entry_point_edges(_pyproject() if pyproject is None else pyproject, _registries()):
        if layer_of(registry) > layer_of(module):
            found.append((module, registry, where))
    return found


def _layer_names(module: str) -> str:
    return "/".join(p or "fkn_bench" for p in LAYERS[layer_of(module)])


def test_every_module_parses_and_has_a_layer() -> None:
    assert "fkn_bench.envs" in MODULES and "fkn_bench.baselines" in MODULES and "fkn_bench.cli" in MODULES
    for module in MODULES:
        layer_of(module)


def test_the_design_table_names_every_package_and_only_packages() -> None:
    tabled = {f"fkn_bench.{p}" if p else "fkn_bench" for layer in LAYERS for p in layer}
    packages = {m for m in MODULES if m.count(".") == 1 and _is_package(m)}
    assert packages - tabled == set(), f"packages missing from the layer table of fkn_bench/DESIGN.md: {sorted(packages - tabled)}"
    assert tabled - set(MODULES) == set(), f"the layer table of fkn_bench/DESIGN.md names no such module: {sorted(tabled - set(MODULES))}"
    package_data = _pyproject()["tool"]["setuptools"]["package-data"]
    assert "DESIGN.md" in package_data.get("fkn_bench", []), "pyproject.toml must ship fkn_bench/DESIGN.md (package-data)"


def test_imports_point_down() -> None:
    found = _layer_violations()
    new = [
        f"{module} (layer {_layer_names(module)}) imports {target} (layer {_layer_names(target)}) at {where}"
        for module, target, where in found
        if (module, target) not in KNOWN_VIOLATIONS
    ]
    assert not new, "imports from a layer above:\n" + "\n".join(new)
    gone = KNOWN_VIOLATIONS - {(module, target) for module, target, _ in found}
    assert not gone, f"fixed, remove from KNOWN_VIOLATIONS: {sorted(gone)}"


def _unresolved() -> list[str]:
    """Imports by string or resource whose name is no module of the package (a module moved
    without its string references following)."""
    found = []
    for module, path in MODULES.items():
        base = module if _is_package(module) else module.rpartition(".")[0]
        for imported in _references(path, base):
            if imported.kind != "import" and imported.target.startswith("fkn_bench") and imported.target not in MODULES:
                found.append(f"{module} names {imported.target!r} ({imported.kind}) at {path}:{imported.line}")
    return found


def test_imports_by_string_name_modules() -> None:
    unresolved = _unresolved()
    assert not unresolved, "imports by string or resource of no module:\n" + "\n".join(unresolved)


def _cycles() -> list[list[str]]:
    """Strongly connected components (Tarjan) of the import-time graph with more than one module
    (or a module importing itself)."""
    graph = {m: sorted({i.target for i in _imports(m) if i.eager}) for m in MODULES}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []

    def connect(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for target in graph[node]:
            if target not in index:
                connect(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1 or node in graph[node]:
                components.append(sorted(component))

    for node in graph:
        if node not in index:
            connect(node)
    return components


def test_no_import_cycles() -> None:
    cycles = _cycles()
    assert not cycles, "modules in import cycles:\n" + "\n".join(" <-> ".join(c) for c in cycles)


@pytest.mark.parametrize(
    ("source", "expected"),
    [
        ("from fkn_bench.harness.grid import CellSpec", ["fkn_bench.harness.grid"]),
        ("from fkn_bench.harness import grid", ["fkn_bench.harness.grid"]),
        ("from fkn_bench.harness import run_grid", ["fkn_bench.harness"]),
        ("import fkn_bench.metrics.scoring as s", ["fkn_bench.metrics.scoring"]),
        ("import numpy", []),
        ("import importlib\nm = importlib.import_module('fkn_bench.harness.grid')", ["fkn_bench.harness.grid"]),
        ("from importlib import import_module\ndef f(n):\n    return import_module(f'fkn_bench.reporting.{n}')", ["fkn_bench.reporting"]),
        ("import importlib\ndef f():\n    return importlib.import_module('.scoring', __name__)", ["fkn_bench.cli.scoring"]),
        ("from fkn_bench.lazy import lazy_exports\n_E = {'a': '.run', 'b': 'fkn_bench.harness.grid'}\n"
         "__getattr__, __dir__ = lazy_exports(__name__, _E, globals())", ["fkn_bench.cli.run", "fkn_bench.harness.grid"]),
        ("SUFFIXES = {'table': '.csv', 'figure': '.png'}", []),
        ("HOTSPOT = 'fkn_bench.filters.ekf:ExtendedKalmanFilter.run'", ["fkn_bench.filters.ekf"]),
        ("TEXT = 'see fkn_bench.filters: the filters'", []),
        ("from importlib import resources\nP = resources.files('fkn_bench.sweep') / 'spaces'", ["fkn_bench.sweep"]),
        ("import importlib.resources\nP = importlib.resources.files('fkn_bench.baselines')", ["fkn_bench.baselines"]),
        ("from importlib.resources import files as f\nP = f('fkn_bench.gates')", ["fkn_bench.gates"]),
    ],
)
def test_import_resolution(source: str, expected: list[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    path = tmp_path / "probe.py"
    path.write_text(source + "\n")
    monkeypatch.setitem(MODULES, "fkn_bench.cli.probe", path)
    monkeypatch.setitem(MODULES, "fkn_bench.cli.scoring", path)  # a sibling for the relative forms
    found = [i.target for i in _imports("fkn_bench.cli.probe")]
    assert [t for t in found if t not in ("fkn_bench.lazy", "fkn_bench.cli.probe")] == expected


def test_the_design_table_is_read_as_written() -> None:
    table = ("intro\n## Layers\n\n| layer | package | holds |\n|---:|---|---|\n| 0 | `fkn_bench` | root |\n"
             "| 0 | `fkn_bench.io` | files (`fkn_bench.lazy` mentioned) |\n| 1 | `fkn_bench.models` | models |\n\n## Next\n"
             "| 2 | `fkn_bench.cli` | not in the section |\n")
    assert layers_from_design(table) == (("", "io"), ("models",))
    with pytest.raises(AssertionError, match="numbered"):
        layers_from_design("## Layers\n| 0 | `fkn_bench` | a |\n| 2 | `fkn_bench.cli` | b |\n")
    with pytest.raises(AssertionError, match="two rows"):
        layers_from_design("## Layers\n| 0 | `fkn_bench.io` | a |\n| 1 | `fkn_bench.io` | b |\n")
    assert LAYERS[0][0] == "" and ("models",) in LAYERS and ("reporting",) in LAYERS
    assert layer_of("fkn_bench.geometry") < layer_of("fkn_bench.models") < layer_of("fkn_bench.filters")
    assert layer_of("fkn_bench.harness") < layer_of("fkn_bench.reporting") < layer_of("fkn_bench.reproduce")


def test_the_checks_catch_what_they_should(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    assert layer_of("fkn_bench.provenance") == 0 < layer_of("fkn_bench.envs.dynamics")
    assert layer_of("fkn_bench.metrics.scoring") < layer_of("fkn_bench.harness") < layer_of("fkn_bench.cli.run")
    probes = {
        "upward": ("def f():\n    from fkn_bench.harness import run_grid\n", "fkn_bench.harness", 2, "import"),  # lazy imports count
        "by_string": ("import importlib\ndef f():\n    return importlib.import_module('fkn_bench.training.pipeline')\n",
                      "fkn_bench.training.pipeline", 3, "string"),
        "by_map": ("from fkn_bench.lazy import lazy_exports\n_E = {\n    'fit': 'fkn_bench.training',\n}\n"
                   "__getattr__, __dir__ = lazy_exports(__name__, _E, globals())\n", "fkn_bench.training", 3, "lazy map"),
        "by_reference": ("GATE = 'fkn_bench.gates.speed:doubled'\n", "fkn_bench.gates.speed", 1, "string"),
        "by_resource": ("from importlib import resources\ndef f():\n    return resources.files('fkn_bench.sweep')\n",
                        "fkn_bench.sweep", 3, "resource"),
    }
    for name, (source, _, _, _) in probes.items():
        (tmp_path / f"{name}.py").write_text(source)
        monkeypatch.setitem(MODULES, f"fkn_bench.metrics.{name}", tmp_path / f"{name}.py")
    found = _layer_violations()
    for name, (_, target, line, kind) in probes.items():
        assert (f"fkn_bench.metrics.{name}", target, f"{tmp_path / name}.py:{line} ({kind})") in found, name

    stale = tmp_path / "stale.py"
    stale.write_text("from fkn_bench.lazy import lazy_exports\n__getattr__, __dir__ = lazy_exports(__name__, {'f': '.gone'}, globals())\n")
    monkeypatch.setitem(MODULES, "fkn_bench.metrics.stale", stale)
    assert any(line.startswith("fkn_bench.metrics.stale names 'fkn_bench.metrics.gone' (lazy map)") for line in _unresolved())

    # an entry point registers into the registry that owns its group: the entry module imports it
    project = {"project": {"entry-points": {"fkn_bench.estimators": {"low": "fkn_bench.metrics.upward"},
                                            "fkn_bench.models": {"toy": "fkn_bench.reporting.tables:register"},
                                            "other.group": {"x": "fkn_bench.metrics.upward"}}}}
    registries = _registries()
    assert registries["fkn_bench.estimators"] == "fkn_bench.estimators.registry"
    assert registries["fkn_bench.models"] == "fkn_bench.models.registry"
    edges = _entry_point_edges(project, registries)
    assert [(m, r) for m, r, _ in edges] == [("fkn_bench.metrics.upward", "fkn_bench.estimators.registry"),
                                             ("fkn_bench.reporting.tables", "fkn_bench.models.registry")]
    assert ("fkn_bench.metrics.upward", "fkn_bench.estimators.registry",
            'pyproject.toml [project.entry-points."fkn_bench.estimators"] low') in _layer_violations(project)
    with pytest.raises(AssertionError, match="not a module"):
        _entry_point_edges({"project": {"entry-points": {"fkn_bench.models": {"gone": "fkn_bench.no_such"}}}}, registries)

    # cycles: import-time imports only; a lazy map or an import inside a function is no edge
    for name, other in (("a", "b"), ("b", "a")):
        (tmp_path / f"{name}.py").write_text(f"from fkn_bench.cli import {other}\n")
        monkeypatch.setitem(MODULES, f"fkn_bench.cli.{name}", tmp_path / f"{name}.py")
    (tmp_path / "c.py").write_text("import importlib\nimportlib.import_module('fkn_bench.cli.d')\n")
    (tmp_path / "d.py").write_text("def f():\n    import fkn_bench.cli.c\n")
    (tmp_path / "e.py").write_text("from fkn_bench.lazy import lazy_exports\n__getattr__, __dir__ = lazy_exports(__name__, {'x': 'fkn_bench.cli.c'}, globals())\n")
    for name in "cde":
        monkeypatch.setitem(MODULES, f"fkn_bench.cli.{name}", tmp_path / f"{name}.py")
    (tmp_path / "d2.py").write_text("import fkn_bench.cli.c\n")
    cycles = _cycles()
    assert ["fkn_bench.cli.a", "fkn_bench.cli.b"] in cycles and not any("fkn_bench.cli.c" in c for c in cycles)
    monkeypatch.setitem(MODULES, "fkn_bench.cli.d", tmp_path / "d2.py")
    assert ["fkn_bench.cli.c", "fkn_bench.cli.d"] in _cycles()  # a module-level import_module is an edge
