"""The package's import graph has no cycle, counting the imports written inside functions.

The graph is built from the source (``ast``), not by importing: every ``import`` and
``from ... import`` statement of every module of ``trackingbox`` is an edge, at module
level or inside a function or class (only ``if TYPE_CHECKING:`` blocks are left out:
they never run). An edge goes to

* the module named, and to every package on its way that is not an ancestor of the
  importing module (importing ``a.b.c`` runs ``a/b/__init__``);
* for ``from P import n``: to ``P.n`` when that is a module; to ``P`` itself unless
  ``P`` is an ancestor package and every name is a submodule of it (``from .. import
  x`` of a non-module ``x`` reads the package, partially initialised while its
  ``__init__`` still runs: a cycle).

A cycle is a strongly connected component of more than one module (or a module
importing itself); the test prints each one as a closed path of edges with their
line numbers.
"""
from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "pyside" / "trackingbox"
ROOT = "trackingbox"


def modules(package: Path = PACKAGE) -> dict[str, Path]:
    """Dotted module name -> file, for every ``.py`` file of the package (``__init__`` is the package)."""
    found: dict[str, Path] = {}
    for path in sorted(package.rglob("*.py")):
        parts = list(path.relative_to(package).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        found[".".join([ROOT, *parts])] = path
    return found


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _imports(tree: ast.AST) -> Iterator[ast.Import | ast.ImportFrom]:
    """Every import statement of *tree* that can run (``if TYPE_CHECKING:`` bodies left out)."""
    stack: list[ast.AST] = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
            continue
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            stack.extend(node.orelse)
            continue
        stack.extend(ast.iter_child_nodes(node))


def _ancestors(name: str) -> set[str]:
    parts = name.split(".")
    return {".".join(parts[:i]) for i in range(1, len(parts))}


def _with_packages(target: str, importer: str, known: dict[str, Path]) -> set[str]:
    """*target* and the packages on its way that importing it runs (the importer's ancestors aside)."""
    parts = target.split(".")
    out = {".".join(parts[:i]) for i in range(2, len(parts) + 1)} - _ancestors(importer)
    return {m for m in out if m in known}


def edges(known: dict[str, Path] | None = None) -> dict[str, dict[str, int]]:
    """module -> {imported module: line of the first import statement making the edge}."""
    known = modules() if known is None else known
    graph: dict[str, dict[str, int]] = {name: {} for name in known}
    for name, path in known.items():
        is_package = path.name == "__init__.py"
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        for node in _imports(tree):
            targets: set[str] = set()
            if isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name == ROOT or alias.name.startswith(ROOT + "."):
                        targets |= _with_packages(alias.name, name, known)
            else:
                if node.level:
                    base = name.split(".") if is_package else name.split(".")[:-1]
                    base = base[: len(base) - (node.level - 1)]
                    source = ".".join(base + ([node.module] if node.module else []))
                else:
                    source = node.module or ""
                if not (source == ROOT or source.startswith(ROOT + ".")):
                    continue
                submodules = {f"{source}.{a.name}" for a in node.names if f"{source}.{a.name}" in known}
                targets |= submodules
                targets |= _with_packages(source, name, known) - {source}
                reads_package = len(submodules) < len(node.names)
                if source in known and (source not in _ancestors(name) or reads_package):
                    targets.add(source)
            for target in targets:
                if target != name or not is_package:
                    graph[name].setdefault(target, node.lineno)
    return graph


def cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """The strongly connected components with a cycle (Tarjan), each sorted, largest first."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    found: list[list[str]] = []
    counter = 0

    def visit(v: str) -> None:
        nonlocal counter
        index[v] = low[v] = counter
        counter += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
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
            if len(component) > 1 or v in graph[v]:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(found, key=lambda c: (-len(c), c))


def closed_path(graph: dict[str, dict[str, int]], component: list[str]) -> list[str]:
    """One cycle through the component's first module, as ``a:line -> b`` steps (breadth-first: shortest)."""
    members = set(component)
    start = component[0]
    previous: dict[str, str] = {}
    queue = [start]
    while queue:
        v = queue.pop(0)
        for w in sorted(graph[v]):
            if w not in members:
                continue
            if w == start:
                path = [v]
                while path[-1] != start:
                    path.append(previous[path[-1]])
                path.reverse()
                path.append(start)
                return [f"{a} (line {graph[a][b]}) -> {b}" for a, b in zip(path, path[1:])]
            if w not in previous:
                previous[w] = v
                queue.append(w)
    return []


def report(graph: dict[str, dict[str, int]]) -> str:
    lines = []
    for component in cycles(graph):
        lines.append(f"cycle of {len(component)} modules: {', '.join(component)}")
        lines.extend(f"    {step}" for step in closed_path(graph, component))
    return "\n".join(lines)


def test_no_import_cycle() -> None:
    graph = edges()
    assert len(graph) > 50 and sum(map(len, graph.values())) > 200  # the package was found and read
    assert not cycles(graph), "import cycles (module-level and function-level imports):\n" + report(graph)


def test_the_graph_sees_every_kind_of_import(tmp_path: Path) -> None:
    """The detector against a small package whose cycles are known by construction."""
    pkg = tmp_path / "trackingbox"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("from .a import f\n__version__ = '1'\n")
    (pkg / "a.py").write_text("def f():\n    from .sub.b import g\n    return g\n")  # function level
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "b.py").write_text("from .. import __version__\n")  # reads the root package
    (pkg / "c.py").write_text("import trackingbox.sub.d\n")  # absolute
    (pkg / "sub" / "d.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                                      "    from .. import c\n")  # never runs: no edge
    (pkg / "e.py").write_text("from . import a\n")  # a submodule: no edge to the package
    graph = edges(modules(pkg))
    assert graph["trackingbox.sub.b"] == {"trackingbox": 1}
    assert graph["trackingbox.a"] == {"trackingbox.sub": 2, "trackingbox.sub.b": 2}
    assert graph["trackingbox.c"] == {"trackingbox.sub": 1, "trackingbox.sub.d": 1}
    assert graph["trackingbox.sub.d"] == {}
    assert graph["trackingbox.e"] == {"trackingbox.a": 1}
    assert cycles(graph) == [["trackingbox", "trackingbox.a", "trackingbox.sub.b"]]
    text = report(graph)
    assert "trackingbox (line 1) -> trackingbox.a" in text and "trackingbox.sub.b (line 1) -> trackingbox" in text


if __name__ == "__main__":
    print(report(edges()) or "no import cycle")
