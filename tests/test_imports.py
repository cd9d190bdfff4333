"""No import cycle between splatbench modules (issue #14); reference/ imports no splatbench.

Every ``import`` statement of every module under ``splatbench/`` counts, wherever it
is written: at the top, inside a function (a late import written to dodge a cycle is
still a cycle: the two modules still need each other), or under ``if TYPE_CHECKING``.
A cycle is broken by moving the shared thing into a module that both sides import.

The graph is read with `ast`, so nothing is imported (no Dr.Jit, no Mitsuba) and the
test runs in well under a second. Edges:

* ``import a.b.c`` -> ``a.b.c``; ``from a.b import c`` -> ``a.b.c`` when ``c`` is a
  module, else ``a.b`` (the package ``__init__``); relative imports are resolved first;
* importing a submodule also runs its parents' ``__init__``; that implicit step is
  not an edge (it is the same for every submodule and cannot be avoided), but an
  explicit ``from a.b import name`` of something defined in ``a/b/__init__.py`` is.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = "splatbench"
ROOT = Path(__file__).resolve().parents[1] / PACKAGE


def module_names(root: Path = ROOT) -> dict[str, Path]:
    """``{dotted name: path}`` of every module of the package (``__init__`` as the package)."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = path.relative_to(root.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def imports_of(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The package modules that ``name`` (at ``path``) imports, anywhere in its body."""
    is_package = path.name == "__init__.py"
    targets: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            targets.update(_known_prefix(alias.name, modules) for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = name.split(".") if is_package else name.split(".")[:-1]
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            for alias in node.names:
                full = f"{base}.{alias.name}"
                targets.add(full if full in modules else _known_prefix(base, modules))
    targets.discard(None)
    targets.discard(name)  # `from splatbench.x import y` inside x's own package __init__ is no cycle
    return {t for t in targets if t is not None}


def _known_prefix(dotted: str, modules: dict[str, Path]) -> str | None:
    """The longest prefix of ``dotted`` that is a package module (None outside the package)."""
    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        candidate = ".".join(parts[:k])
        if candidate in modules:
            return candidate
    return None


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    modules = module_names(root)
    return {name: imports_of(name, path, modules) for name, path in modules.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
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
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


def _example(component: list[str], graph: dict[str, set[str]]) -> str:
    """One concrete loop inside ``component``, e.g. ``a -> b -> a`` (for the failure message)."""
    members = set(component)
    start = component[0]
    path, seen = [start], {start}
    node = start
    while True:
        nxt = sorted(graph[node] & members)
        back = [w for w in nxt if w in seen]
        if back:
            return " -> ".join(path[path.index(back[0]):] + [back[0]])
        node = next(w for w in nxt if w not in seen)
        path.append(node)
        seen.add(node)


def test_cycle_finder_sees_function_level_and_relative_imports(tmp_path):
    """The finder itself: a late import inside a function and a relative import both close a loop."""
    pkg = tmp_path / PACKAGE
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from splatbench.sub import b\n")
    (pkg / "sub" / "b.py").write_text("def f():\n    from .. import c\n")
    (pkg / "c.py").write_text("import os\n\ndef g():\n    import splatbench.a\n")
    (pkg / "d.py").write_text("from splatbench import a\n")  # imports into the loop, is not part of it
    graph = import_graph(pkg)
    assert graph["splatbench.sub.b"] == {"splatbench.c"}
    assert cycles(graph) == [["splatbench.a", "splatbench.c", "splatbench.sub.b"]]


def test_no_import_cycle_between_splatbench_modules():
    graph = import_graph()
    assert len(graph) > 50, f"found only {len(graph)} modules under {ROOT}"  # the walk saw the package
    found = cycles(graph)
    assert not found, "import cycles (move the shared thing to a module both import):\n" + "\n".join(
        f"  {_example(c, graph)}   [component: {', '.join(c)}]" for c in found)


def test_reference_imports_nothing_from_splatbench():
    """The float64 oracle is written from docs/conventions.md alone (reference/__init__.py):
    no statement in it, at any level, imports splatbench."""
    offenders = []
    for path in sorted((ROOT.parent / "reference").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0 else []
            offenders += [f"{path.name}:{node.lineno} {n}" for n in names if n.split(".")[0] == PACKAGE]
    assert not offenders, f"reference/ imports splatbench: {offenders}"


if __name__ == "__main__":  # `python tests/test_imports.py` lists the cycles
    g = import_graph()
    for comp in cycles(g):
        print(_example(comp, g), "  [", ", ".join(comp), "]")
    raise SystemExit(pytest.main([__file__, "-q"]))
