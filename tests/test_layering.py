"""The layers point one way: the library knows nothing of the simulator, the service or
the benchmarks (docs/ARCHITECTURE.md).

The import graph is read from the source with :mod:`ast` (every ``import``, also those
inside functions: a deferred import is still an arrow), so the test needs none of the
optional packages.  A subprocess checks what ``import alloc`` really loads.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("alloc", "sim", "service", "benchmarks")

#: package -> the project packages it may import (besides itself)
ALLOWED: dict[str, set[str]] = {
    "alloc": set(),
    "sim": {"alloc"},
    "service": {"alloc"},
    "benchmarks": {"alloc", "sim", "service"},
}

#: third-party packages the core may import at module level (``[project] dependencies``);
#: anything else (solver front-ends, plotting) only inside the function that needs it.
CORE_THIRD_PARTY = {"numpy", "scipy", "numba", "typer"}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path) -> list[tuple[str, int, bool]]:
    """``(imported module, line, at module level)`` for every import in ``path``."""
    name = _module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    tree = ast.parse(path.read_text(), filename=str(path))
    top_level = {id(node) for node in tree.body}
    # imports under ``if TYPE_CHECKING:`` at module level are not executed
    typing_only = {id(n) for node in tree.body if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)
                   for n in ast.walk(node)}
    out = []
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        if isinstance(node, ast.Import):
            out += [(alias.name, node.lineno, id(node) in top_level) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            out.append((target, node.lineno, id(node) in top_level))
    return out


def _source_files() -> list[Path]:
    return sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py"))


def test_the_tree_is_read():
    files = _source_files()
    assert len(files) > 40 and any(f.name == "api.py" for f in files)


@pytest.mark.parametrize("path", _source_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_imports_point_down_the_layers(path):
    layer = path.relative_to(ROOT).parts[0]
    wrong = [f"{path.relative_to(ROOT)}:{line} imports {target}"
             for target, line, _ in _imports(path)
             if target.split(".")[0] in PACKAGES and target.split(".")[0] != layer
             and target.split(".")[0] not in ALLOWED[layer]]
    assert not wrong, "imports against the layering:\n" + "\n".join(wrong)


#: inside the core: sub-package -> the sibling sub-packages it must not import (geometry is
#: geometry: the allocation methods build on ``alloc.ams``'s public API, never the reverse)
FORBIDDEN_INSIDE_CORE: dict[str, set[str]] = {"alloc.ams": {"alloc.methods"}}


def _forbidden_core_imports(path: Path) -> list[str]:
    name = _module_name(path)
    return [f"{path.relative_to(ROOT)}:{line} imports {target}"
            for package, banned in FORBIDDEN_INSIDE_CORE.items() if name == package or name.startswith(package + ".")
            for target, line, _ in _imports(path)
            if any(target == b or target.startswith(b + ".") for b in banned)]


@pytest.mark.parametrize("path", sorted((ROOT / "alloc" / "ams").rglob("*.py")), ids=lambda p: str(p.relative_to(ROOT)))
def test_geometry_imports_no_allocation_method(path):
    wrong = _forbidden_core_imports(path)
    assert not wrong, "alloc.ams is geometry; it must not import the methods:\n" + "\n".join(wrong)


def test_geometry_rule_catches_an_import_of_the_methods(monkeypatch):
    """The rule above fails on a module of ``alloc.ams`` importing ``alloc.methods`` in any form."""
    fake = ROOT / "alloc" / "ams" / "_layering_probe.py"
    for src in ("from ..methods.direct import DirectAllocation\n",
                "def f():\n    from alloc.methods import facet_search\n",
                "import alloc.methods.facet_search\n"):
        monkeypatch.setattr(Path, "read_text", lambda self, _src=src, _orig=Path.read_text:
                            _src if self == fake else _orig(self))
        assert _forbidden_core_imports(fake), src
    monkeypatch.undo()
    assert not _forbidden_core_imports(ROOT / "alloc" / "ams" / "geometry.py")


def test_importing_geometry_loads_no_method():
    loaded = _loaded_after("import alloc.ams")
    assert [m for m in loaded if m.startswith("alloc.methods")] == []


@pytest.mark.parametrize("path", sorted((ROOT / "alloc").rglob("*.py")), ids=lambda p: str(p.relative_to(ROOT)))
def test_core_imports_only_base_dependencies_at_module_level(path):
    stdlib = set(sys.stdlib_module_names) | {"__future__"}
    wrong = [f"{path.relative_to(ROOT)}:{line} imports {target} at module level"
             for target, line, top in _imports(path)
             if top and target.split(".")[0] not in stdlib | CORE_THIRD_PARTY | {"alloc"}]
    assert not wrong, "optional packages must be imported where they are used:\n" + "\n".join(wrong)


def _top_level_graph() -> dict[str, set[str]]:
    modules = {_module_name(p): p for p in (ROOT / "alloc").rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        edges = set()
        for target, _, top in _imports(path):
            if not top or not target.startswith("alloc"):
                continue
            # ``from . import x`` names a submodule when one exists
            edges.add(target)
        graph[name] = {t for t in edges if t in modules and t != name}
    return graph


def test_core_has_no_import_cycle_between_modules():
    """Module-level imports inside ``alloc`` form no cycle (package ``__init__`` files aside:
    importing a submodule always runs its package first, that is not a dependency)."""
    graph = {m: {t for t in ts if not m.startswith(t + ".")} for m, ts in _top_level_graph().items()}
    packages = {m for m in graph if (ROOT / m.replace(".", "/") / "__init__.py").exists()}
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if nxt in packages:
                continue
            if state.get(nxt) == 1:
                cycle = stack[stack.index(nxt):] + [nxt]
                pytest.fail("import cycle: " + " -> ".join(cycle))
            if nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node)


def _loaded_after(code: str) -> list[str]:
    out = subprocess.run([sys.executable, "-c", code + "\nimport sys, json; print(json.dumps(sorted(sys.modules)))"],
                         capture_output=True, text=True, check=True, cwd=ROOT)
    return json.loads(out.stdout.splitlines()[-1])


def test_import_alloc_loads_no_method_and_no_upper_layer():
    loaded = _loaded_after("import alloc")
    heavy = [m for m in loaded if m.split(".")[0] in {"sim", "service", "benchmarks", "numba", "scipy", "fastapi", "dask",
                                                       "cvxpy", "matplotlib", "qpsolvers"}]
    assert heavy == []
    assert [m for m in loaded if m.startswith("alloc.methods") or m.startswith("alloc.ams")] == []


def test_building_one_allocator_loads_no_upper_layer():
    loaded = _loaded_after("import alloc\nalloc.make_allocator(alloc.Problem([[1.0, 2.0]], [-1, -1], [1, 1]), 'pinv')")
    assert "alloc.methods.pseudo_inverse" in loaded
    assert [m for m in loaded if m.split(".")[0] in {"sim", "service", "benchmarks", "fastapi", "dask", "cvxpy",
                                                    "matplotlib"}] == []


def test_cli_help_imports_no_plugin_and_no_kernel():
    loaded = _loaded_after("import sys\nsys.argv = ['alloc', '--help']\nfrom alloc.cli import app\n"
                           "try:\n    app()\nexcept SystemExit:\n    pass")
    assert [m for m in loaded if m.split(".")[0] in {"sim", "service", "benchmarks", "numba", "scipy"}] == []
    assert "alloc.api" not in loaded and "alloc.ams" not in loaded


# ------------------------------------------------------- the alloc command's plugins
def test_version_is_the_package_version():
    from typer.testing import CliRunner

    import alloc
    from alloc.cli import app

    out = CliRunner().invoke(app, ["--version"])
    assert out.exit_code == 0 and out.output.strip() == f"alloc {alloc.__version__}"


def test_plugins_are_the_declared_entry_points():
    """pyproject.toml declares sim, bench, serve; the installed metadata must match it."""
    import tomllib

    from alloc.cli import command_entry_points

    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"]["alloc.commands"]
    found = {name: ep.value for name, ep in command_entry_points().items() if name != "ams"}
    assert found == declared, "reinstall the project (pip install -e .): its entry points changed"
    for value in declared.values():
        module = value.split(":")[0]
        assert module.split(".")[0] in {"sim", "service", "benchmarks"}


def test_missing_extra_is_named():
    from importlib.metadata import EntryPoint

    from alloc.cli import missing_requirements

    class Dist:
        requires = ['fastapi>=0.1; extra == "service"', 'surely-absent-pkg-1e9>=1; extra == "service"',
                    'alloc[service,sim]; extra == "bench"', 'also-absent-pkg-1e9; extra == "sim"', "numpy>=1"]
        metadata = {"Name": "alloc"}

    def ep(extra: str) -> EntryPoint:
        return EntryPoint("x", f"service.cli:serve_command [{extra}]", "alloc.commands")._for(Dist())

    assert missing_requirements(ep("service")) == ["surely-absent-pkg-1e9"]
    assert missing_requirements(ep("bench")) == ["also-absent-pkg-1e9", "surely-absent-pkg-1e9"]
    assert missing_requirements(EntryPoint("x", "service.cli:serve_command", "alloc.commands")) == []
