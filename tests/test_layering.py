"""The layers point one way and form no circle: the library knows nothing of the simulator,
the service or the benchmarks (docs/ARCHITECTURE.md), and no module depends on itself
through others.

The import graph is read from the source with :mod:`ast`, so the test needs none of the
optional packages.  Every arrow counts: module-level imports, imports inside functions (a
deferred import is still a dependency), imports under ``if TYPE_CHECKING:`` (not executed,
but a module that names another's type depends on it: a cycle through one is a cycle) and
``importlib.import_module`` calls (resolved from their literal argument, or from the table
the call reads: see :func:`_dynamic_targets`; a call the reader cannot resolve fails the
test).  Importing a submodule
runs its package's ``__init__`` first; that is not a dependency of the importer, so
``import a.b.c`` is one arrow, to ``a.b.c``; ``from a.b import name`` is an arrow to the
submodule ``a.b.name`` when there is one, else to the package ``a.b`` (its ``__init__``).
A subprocess checks what ``import alloc`` really loads.
"""

from __future__ import annotations

import ast
import functools
import json
import subprocess
import sys
from collections.abc import Iterable
from dataclasses import dataclass
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


@dataclass(frozen=True)
class Arrow:
    """One dependency of a module: ``target`` imported at ``line``, how (``kind``)."""

    target: str
    line: int
    kind: str  # "module level", "deferred", "type-only" or "importlib"
    top: bool  # executed when the module is imported (module level, outside functions)


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _resolve(package: str, level: int, module: str | None) -> str:
    """The absolute name of ``from <level dots><module> import ...`` inside ``package``."""
    base = package.split(".")
    base = base[:len(base) - (level - 1)]
    return ".".join(base + ([module] if module else []))


def _is_import_module(call: ast.Call) -> bool:
    f = call.func
    name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", None)
    return name in {"import_module", "__import__"} and bool(call.args)


def _module_dicts(tree: ast.Module) -> dict[str, list[str]]:
    """Module-level ``NAME = {...}`` / ``NAME: ... = {...}`` dict literals: their string values."""
    out: dict[str, list[str]] = {}
    for node in tree.body:
        targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(node, ast.AnnAssign) else []
        value = getattr(node, "value", None)
        if isinstance(value, ast.Dict) and len(targets) == 1 and isinstance(targets[0], ast.Name):
            out[targets[0].id] = [v.value for v in value.values if isinstance(v, ast.Constant) and isinstance(v.value, str)]
    return out


def _dict_read_into(function: ast.AST | None, name: str, dicts: dict[str, list[str]]) -> list[str] | None:
    """The values of the module-level dict that ``name`` is read from in ``function``
    (``name = TABLE.get(key)`` or ``name = TABLE[key]``), or None."""
    if function is None:
        return None
    for node in ast.walk(function):
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == name for t in node.targets):
            v = node.value
            if isinstance(v, ast.Call) and isinstance(v.func, ast.Attribute) and v.func.attr == "get":
                v = v.func.value
            elif isinstance(v, ast.Subscript):
                v = v.value
            if isinstance(v, ast.Name) and v.id in dicts:
                return dicts[v.id]
    return None


def _dynamic_targets(arg: ast.expr, package: str, function: ast.AST | None, dicts: dict[str, list[str]],
                     modules: Iterable[str]) -> list[str] | None:
    """The modules an ``import_module(arg)`` call can load, or None when they cannot be told.

    * a literal (relative literals against the module's package);
    * a name read from a module-level dict literal in the same function (``module =
      _LAZY.get(name)``), or an f-string of one such name (``f".{module}"``): the dict's values;
    * an f-string with a literal prefix ending in a dot (``f"sim.scenarios.{name}"``): every
      module under that prefix.
    """
    def absolute(name: str) -> str:
        if name.startswith("."):
            level = len(name) - len(name.lstrip("."))
            return _resolve(package, level, name.lstrip(".") or None)
        return name

    if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
        return [absolute(arg.value)]
    if isinstance(arg, ast.Name):
        values = _dict_read_into(function, arg.id, dicts)
        return None if values is None else [absolute(v) for v in values]
    if isinstance(arg, ast.JoinedStr):
        parts = arg.values
        names = [p.value for p in parts if isinstance(p, ast.FormattedValue)]
        if len(names) == 1 and isinstance(names[0], ast.Name):
            values = _dict_read_into(function, names[0].id, dicts)
            if values is not None:
                def fill(value: str) -> str:
                    return "".join(p.value if isinstance(p, ast.Constant) else value for p in parts)
                return [absolute(fill(v)) for v in values]
        prefix = parts[0].value if parts and isinstance(parts[0], ast.Constant) else ""
        if prefix.endswith(".") and len(prefix) > 1:
            base = absolute(prefix[:-1]) if prefix.startswith(".") else prefix[:-1]
            return sorted(m for m in modules if m.startswith(base + "."))
    return None


def _arrows_of(name: str, source: str, is_package: bool, modules: Iterable[str] = ()) -> list[Arrow]:
    """Every arrow of module ``name`` (``source``; ``is_package``: it is an ``__init__``).
    A dynamic import the reader cannot resolve is an arrow to ``"?"``."""
    modules = set(modules)
    package = name if is_package else name.rpartition(".")[0]
    tree = ast.parse(source)
    dicts = _module_dicts(tree)
    out: list[Arrow] = []
    # one walk: (node, the outermost function it is in, at module level, under TYPE_CHECKING)
    todo: list[tuple[ast.AST, ast.AST | None, bool, bool]] = [(node, None, True, False)
                                                              for node in reversed(tree.body)]
    while todo:
        node, fn, top, typing_only = todo.pop()
        if top and isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            # the body is not executed (not `top`) but is a dependency all the same
            todo += [(n, fn, False, True) for n in reversed(node.body)]
            todo += [(n, fn, False, False) for n in reversed(node.orelse)]
            continue
        kind = "type-only" if typing_only else "deferred" if fn is not None else "module level"
        if isinstance(node, ast.Import):
            out += [Arrow(alias.name, node.lineno, kind, top) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            target = _resolve(package, node.level, node.module) if node.level else node.module or ""
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                out.append(Arrow(sub if sub in modules else target, node.lineno, kind, top))
        elif isinstance(node, ast.Call) and _is_import_module(node):
            targets = _dynamic_targets(node.args[0], package, fn, dicts, modules)
            out += [Arrow(t, node.lineno, "importlib", False) for t in (targets if targets is not None else ["?"])]
        inner = node if fn is None and isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) else fn
        todo += [(child, inner, False, typing_only) for child in reversed(list(ast.iter_child_nodes(node)))]
    return out


@functools.lru_cache(maxsize=1)
def _project_modules() -> dict[str, Path]:
    return {_module_name(p): p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")}


def _imports(path: Path) -> list[tuple[str, int, bool]]:
    """``(imported module, line, at module level)`` for every arrow of ``path``."""
    arrows = _arrows_of(_module_name(path), path.read_text(), path.name == "__init__.py", _project_modules())
    return [(a.target, a.line, a.top) for a in arrows]


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


def _graph(sources: dict[str, tuple[str, bool]]) -> dict[str, dict[str, Arrow]]:
    """module -> {imported project module: its first arrow}, over ``{module: (source, is_package)}``."""
    graph: dict[str, dict[str, Arrow]] = {}
    for name, (source, is_package) in sources.items():
        edges: dict[str, Arrow] = {}
        for arrow in _arrows_of(name, source, is_package, sources):
            if arrow.target in sources and arrow.target != name:
                edges.setdefault(arrow.target, arrow)
        graph[name] = edges
    return graph


def _unresolved(sources: dict[str, tuple[str, bool]]) -> list[str]:
    return [f"{name}:{a.line}" for name, (source, is_package) in sources.items()
            for a in _arrows_of(name, source, is_package, sources) if a.target == "?"]


def _cycles(graph: dict[str, dict[str, Arrow]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each as its
    sorted modules; :func:`_closed_path` gives a cycle through one for a message."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def connect(v: str) -> None:  # recursion depth <= number of modules (a few hundred)
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            connect(v)
    return sorted(components)


def _closed_path(graph: dict[str, dict[str, Arrow]], component: set[str]) -> list[str]:
    """A shortest cycle through the component's first module (breadth first)."""
    start = min(component)
    parent: dict[str, str] = {}
    frontier = [start]
    while frontier:
        nxt = []
        for v in frontier:
            for w in sorted(graph[v]):
                if w not in component:
                    continue
                if w == start:
                    path = [v]
                    while path[-1] != start:
                        path.append(parent[path[-1]])
                    return [start, *reversed(path[:-1]), start] if len(path) > 1 else [start, v, start]
                if w not in parent:
                    parent[w] = v
                    nxt.append(w)
        frontier = nxt
    raise AssertionError(f"no cycle through {start}")  # pragma: no cover - a component has one


def _describe(graph: dict[str, dict[str, Arrow]], component: list[str]) -> str:
    path = _closed_path(graph, set(component))
    return f"{len(component)} modules: " + " -> ".join(path) + "\n" + "\n".join(
        f"    {a} -> {b} ({graph[a][b].kind}, line {graph[a][b].line})" for a, b in zip(path, path[1:]))


def _project_sources() -> dict[str, tuple[str, bool]]:
    return {name: (path.read_text(), path.name == "__init__.py") for name, path in _project_modules().items()}


@functools.lru_cache(maxsize=1)
def _project_graph() -> dict[str, dict[str, Arrow]]:
    return _graph(_project_sources())


#: Cycles known and not yet broken, each with the agent or owner that breaks it: the modules of
#: the cycle (``pkg.*``: any module under ``pkg``).  A listed cycle is reported as an expected
#: failure while it exists; any other cycle (or a listed one that grew by a module) fails
#: :func:`test_no_import_cycle_between_modules`, and so does a listed cycle that no longer
#: exists (the entry is stale: remove it).  None at present.
KNOWN_CYCLES: dict[frozenset[str], str] = {}


def _known(component: list[str], known: dict[frozenset[str], str]) -> frozenset[str] | None:
    """The ``known`` entry ``component`` is, or None."""
    for entry in known:
        exact = {m for m in entry if not m.endswith(".*")}
        under = tuple(m[:-1] for m in entry if m.endswith(".*"))
        if exact <= set(component) and all(m in exact or m.startswith(under or ("\0",)) for m in component):
            return entry
    return None


def _cycle_report(graph: dict[str, dict[str, Arrow]], known: dict[frozenset[str], str]) -> tuple[
        list[list[str]], list[frozenset[str]], list[list[str]]]:
    """``(new cycles, stale entries of known, known cycles still there)``."""
    cycles = _cycles(graph)
    new = [c for c in cycles if _known(c, known) is None]
    present = [c for c in cycles if _known(c, known) is not None]
    stale = [entry for entry in known if not any(_known(c, known) == entry for c in cycles)]
    return new, stale, present


def test_no_dynamic_import_is_left_unresolved():
    unresolved = _unresolved(_project_sources())
    assert not unresolved, ("import_module calls whose targets the layering test cannot tell (use a literal or a "
                            "module-level dict of module names):\n" + "\n".join(unresolved))


def test_no_import_cycle_between_modules():
    """Counting module-level, deferred, type-only and ``importlib`` arrows, across all four packages."""
    graph = _project_graph()
    new, stale, present = _cycle_report(graph, KNOWN_CYCLES)
    assert not new, "import cycles:\n" + "\n".join(_describe(graph, c) for c in new)
    assert not stale, "KNOWN_CYCLES lists cycles that no longer exist; remove:\n" + "\n".join(
        " <-> ".join(sorted(entry)) for entry in stale)
    if present:
        pytest.xfail("known cycles:\n" + "\n".join(
            f"{KNOWN_CYCLES[_known(c, KNOWN_CYCLES)]}: {_describe(graph, c)}" for c in present))


def test_a_stale_or_grown_known_cycle_is_reported():
    """A listed cycle that is gone is stale; one that gained a module is a new cycle."""
    sources = {"pkg": ("", True), "pkg.a": ("import pkg.b\n", False), "pkg.b": ("import pkg.c\n", False),
               "pkg.c": ("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import pkg.b\n", False)}
    graph = _graph(sources)
    gone = frozenset({"pkg.a", "pkg.c"})
    assert _cycle_report(graph, {gone: "x", frozenset({"pkg.b", "pkg.c"}): "y"}) == ([], [gone], [["pkg.b", "pkg.c"]])
    sources["pkg.c"] = ("import pkg.a\n", False)  # the cycle grew: a, b, c
    assert _cycle_report(_graph(sources), {frozenset({"pkg.b", "pkg.c"}): "y"}) == (
        [["pkg.a", "pkg.b", "pkg.c"]], [frozenset({"pkg.b", "pkg.c"})], [])


def test_the_cycle_finder_counts_deferred_and_importlib_arrows():
    """Seeded generator of module graphs: a random DAG has no cycle; one back arrow of any
    kind (module level, in a function, under ``TYPE_CHECKING``, ``importlib`` literal,
    relative, from a dict of names, through a package ``__init__``) closes one, and the
    finder names its modules."""
    import random

    rng = random.Random(20261201)
    forms = [
        lambda a, b, i: f"import {b}\n",
        lambda a, b, i: f"def f{i}():\n    import {b}\n",
        lambda a, b, i: f"def f{i}():\n    from {b} import thing\n",
        lambda a, b, i: f"from typing import TYPE_CHECKING\n\nif TYPE_CHECKING:\n    from {b} import Thing{i}\n",
        lambda a, b, i: f"import importlib\n\n\ndef f{i}():\n    importlib.import_module({b!r})\n",
        lambda a, b, i: f"from importlib import import_module\n\n\ndef f{i}():\n    import_module('.{b[4:]}', __package__)\n",
        lambda a, b, i: (f"import importlib\n_TABLE{i} = {{'x': {b!r}}}\n\n\ndef f{i}(k):\n"
                         f"    module = _TABLE{i}.get(k)\n    return importlib.import_module(module)\n"),
        lambda a, b, i: (f"from importlib import import_module\n_LAZY{i} = {{'x': {b[4:]!r}}}\n\n\n"
                         f"def f{i}(name):\n    module = _LAZY{i}[name]\n    return import_module(f'pkg.{{module}}')\n"),
    ]
    for trial in range(60):
        n = rng.randint(3, 9)
        order = rng.sample([f"pkg.m{i}" for i in range(n)], n)  # arrows only forward in this order: a DAG
        body = {m: "" for m in order}
        count = 0
        for i, a in enumerate(order):
            for j, b in enumerate(order[i + 1:], i + 1):
                if j == i + 1 or rng.random() < 0.3:  # a chain through all, and more
                    count += 1
                    body[a] += rng.choice(forms)(a, b, count)
        sources = {"pkg": ("", True), **{m: (src, False) for m, src in body.items()}}
        assert _cycles(_graph(sources)) == [], (trial, sources)
        lo, hi = sorted(rng.sample(range(n), 2))
        back = rng.choice(forms)(order[hi], order[lo], 0)
        sources[order[hi]] = (sources[order[hi]][0] + back, False)
        graph = _graph(sources)
        cycles = _cycles(graph)
        assert cycles == [sorted(order[lo:hi + 1])], (trial, back, cycles)
        path = _closed_path(graph, set(cycles[0]))
        assert path[0] == path[-1] and all(b in graph[a] for a, b in zip(path, path[1:])), path
    # through a package: ``from pkg import name`` runs pkg/__init__, which imports pkg.m0
    sources = {"pkg": ("from .m0 import thing\n", True), "pkg.m0": ("def f():\n    from pkg import other\n", False)}
    assert _cycles(_graph(sources)) == [["pkg", "pkg.m0"]]
    # a submodule imported by its full name is not an arrow to its package
    sources = {"pkg": ("from .m0 import thing\n", True), "pkg.m0": ("import pkg.m1\n", False), "pkg.m1": ("", False)}
    assert _cycles(_graph(sources)) == []
    # an argument the reader cannot tell is reported, not ignored
    sources = {"pkg": ("", True), "pkg.m0": ("import importlib\n\n\ndef f(x):\n    importlib.import_module(x)\n", False)}
    assert _unresolved(sources) == ["pkg.m0:5"]


def test_the_core_graph_is_read_with_its_lazy_names():
    """The facade packages' lazy names (``alloc/__init__``, ``alloc/ams/__init__``) are arrows."""
    graph = _project_graph()
    assert {"alloc.api", "alloc.problem", "alloc.registry"} <= set(graph["alloc"])
    # the kernel caches are placed by the kernel modules, not by the package (alloc._engine._kernel_cache)
    assert "alloc._engine._jit_cache" not in graph["alloc"] and "alloc._engine._kernel_cache" in graph["alloc._engine._active_set"]
    assert {"alloc.ams.geometry", "alloc.ams.coverage"} <= set(graph["alloc.ams"])
    assert "alloc.methods" in graph["alloc.registry"]  # the registry's look-ups load the built-in methods
    # the failure kinds build on the problem (Problem.with_health applies an effector's health)
    assert "alloc.problem" in graph["alloc.health"] and "alloc.health" not in graph["alloc.problem"]


def _module_level_switches(path: Path) -> list[str]:
    """Module-level names in capitals bound to ``True``/``False`` (also inside a module-level
    ``if``/``try``): a switch that changes behaviour when flipped."""
    out = []
    todo = list(ast.parse(path.read_text()).body)
    while todo:
        node = todo.pop()
        if isinstance(node, (ast.If, ast.Try)):
            todo += [*node.body, *node.orelse, *getattr(node, "finalbody", []),
                     *(n for h in getattr(node, "handlers", []) for n in h.body)]
        elif isinstance(node, (ast.Assign, ast.AnnAssign)) and isinstance(node.value, ast.Constant) \
                and isinstance(node.value.value, bool):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            out += [f"{path.relative_to(ROOT)}:{node.lineno} {t.id}" for t in targets
                    if isinstance(t, ast.Name) and t.id.isupper()]
    return out


def test_the_library_has_no_module_level_switches(monkeypatch):
    """Behaviour is chosen by arguments and options, never by flipping a module constant
    (``alloc._engine._active_set.WARM_START`` guarded dead branches; ``alloc.api.FAST_CALL`` applied
    half-way when flipped)."""
    found = [s for path in sorted((ROOT / "alloc").rglob("*.py")) for s in _module_level_switches(path)]
    assert found == []
    # the rule reads module-level try/except and if blocks too
    fake = ROOT / "alloc" / "_switch_probe.py"
    source = "try:\n    import x\n    FAST = True\nexcept ImportError:\n    FAST = False\nif x:\n    SLOW: bool = True\n"
    monkeypatch.setattr(Path, "read_text", lambda self, _orig=Path.read_text: source if self == fake else _orig(self))
    assert [f.split()[-1] for f in _module_level_switches(fake)] == ["SLOW", "FAST", "FAST"]


def test_the_c_call_path_is_a_fact_of_the_class():
    """``has_c_call_path()`` says which base the allocator has; nothing else decides it."""
    import alloc
    from alloc import api

    try:
        from alloc._engine._fastcall import FastCall
    except ImportError:  # pragma: no cover - a build without a C compiler
        assert not api.has_c_call_path() and not hasattr(alloc.Allocator, "_fast_setup")
    else:
        assert api.has_c_call_path() and issubclass(alloc.Allocator, FastCall)
    assert not hasattr(api, "FAST_CALL")


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

    from alloc.cli import _BUILTIN, command_entry_points

    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"]["alloc.commands"]
    builtin = {ep.name for ep in _BUILTIN}  # the library's own sub-applications (ams, replay)
    assert builtin == {"ams", "replay"}
    found = {name: ep.value for name, ep in command_entry_points().items() if name not in builtin}
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
