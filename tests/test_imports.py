"""The layers of docs/architecture.md, enforced; no import cycle between splatbench modules
(issue #14); reference/ imports no splatbench.

Every import of a splatbench module is checked against the table in docs/architecture.md
(read from the file, so the table is the rule): a module may import its own part, the
parts its row names, and any lower level; a failure names the file, the line, the import
and the rule.

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
  explicit ``from a.b import name`` of something defined in ``a/b/__init__.py`` is;
* a string that is exactly a package module's dotted name (``"splatbench.raster"``, or
  ``"splatbench.commands.sfm:sfm"``) is an edge to that module: it is there to be
  imported by name (a lazy export, a registry).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path
from typing import NamedTuple

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


class Import(NamedTuple):
    """One import statement's package module: where it is written and what it names."""

    line: int
    target: str
    main: bool  # written under the module's ``if __name__ == "__main__":`` block
    by_string: bool = False  # a string naming the module (`STRING_IMPORT`), imported by name later


def import_edges(name: str, path: Path, modules: dict[str, Path]) -> list[Import]:
    """Every import of a package module that ``name`` (at ``path``) makes, anywhere in its body."""
    is_package = path.name == "__init__.py"
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    main_lines = {n.lineno for block in tree.body if _is_main_block(block) for n in ast.walk(block)
                  if hasattr(n, "lineno")}
    out: list[Import] = []
    for node in ast.walk(tree):
        targets: list[str | None] = []
        by_string = False
        if isinstance(node, ast.Import):
            targets = [_known_prefix(alias.name, modules) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = name.split(".") if is_package else name.split(".")[:-1]
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            for alias in node.names:
                full = f"{base}.{alias.name}"
                targets.append(full if full in modules else _known_prefix(base, modules))
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and STRING_IMPORT.match(node.value) \
                and node.value.split(":")[0] in modules:
            # a module named by a string for a late `importlib.import_module` (a lazy export, a
            # command or kind registry): the same dependency, written where a reader does not look
            targets = [node.value.split(":")[0]]
            by_string = True
        # `from splatbench.x import y` inside x's own package __init__ is no cycle
        out += [Import(node.lineno, t, node.lineno in main_lines, by_string) for t in targets
                if t is not None and t != name]
    return sorted(set(out))


#: A string that names a package module (``splatbench.a.b``, or ``splatbench.a.b:attr`` as the
#: command and kind registries write them): counted as an import of that module.
STRING_IMPORT = re.compile(rf"^{PACKAGE}(\.[A-Za-z_]\w*)+(:[A-Za-z_]\w*)?$")


def _is_main_block(node: ast.stmt) -> bool:
    return isinstance(node, ast.If) and isinstance(node.test, ast.Compare) and \
        isinstance(node.test.left, ast.Name) and node.test.left.id == "__name__"


def imports_of(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The package modules that ``name`` (at ``path``) imports by statement, anywhere in its
    body: the cycle graph. A registry that names its plugins by string while they import its
    base types is the plugin pattern (entry points work the same way), not a cycle; the layer
    check counts those strings too."""
    return {i.target for i in import_edges(name, path, modules) if not i.by_string}


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

# --------------------------------------------------------------------------- the layer table
ARCHITECTURE = ROOT.parent / "docs" / "architecture.md"


class Part(NamedTuple):
    """One row of the layer table."""

    level: int
    name: str
    modules: tuple[str, ...]
    also: frozenset[str]   # sibling parts it may import
    rule: str


#: Imports that run against the table today, each with its reason; the list only shrinks
#: (`test_known_exceptions_still_occur` fails once one is gone).
KNOWN_EXCEPTIONS: dict[tuple[str, str], str] = {}


def layer_table(path: Path = ARCHITECTURE) -> list[Part]:
    """The rows of the first markdown table of ``path`` whose header starts ``| Level |``."""
    parts, rows = [], False
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("| Level |"):
            rows = True
            continue
        if rows and line.startswith("|---"):
            continue
        if rows and not line.startswith("|"):
            break
        if rows:
            level, name, modules, also, rule = (c.strip() for c in line.strip().strip("|").split("|"))
            parts.append(Part(int(level), name, tuple(re.findall(r"`([\w.]+)`", modules)),
                              frozenset(a.strip() for a in also.split(",") if a.strip()), rule))
    return parts


def part_of(module: str, parts: list[Part]) -> Part | None:
    """The row whose module is the longest dotted prefix of ``module`` (``splatbench`` alone
    matches only the package's own ``__init__``)."""
    best, length = None, -1
    for part in parts:
        for prefix in part.modules:
            hit = module == prefix or (prefix != "splatbench" and module.startswith(prefix + "."))
            if hit and len(prefix) > length:
                best, length = part, len(prefix)
    return best


def allowed(src: Part, dst: Part) -> bool:
    return dst.level < src.level or dst.name == src.name or dst.name in src.also


def violations(root: Path = ROOT, table: Path = ARCHITECTURE) -> list[tuple[str, str, str]]:
    """``(module, target, message)`` of every import that runs against the table."""
    parts = layer_table(table)
    entry = max(parts, key=lambda p: p.level)
    modules = module_names(root)
    out = []
    for name, path in modules.items():
        src = part_of(name, parts)
        for imp in import_edges(name, path, modules):
            dst = part_of(imp.target, parts)
            here = entry if imp.main else src
            if src is None or dst is None or allowed(here, dst):
                continue
            where = f"{path.relative_to(root.parent)}:{imp.line}"
            may = "".join(f"{a}, " for a in sorted(src.also))
            out.append((name, imp.target, f"{where} imports {imp.target} ({dst.name}, level {dst.level}): "
                                          f"{src.name} (level {src.level}) may import only {src.name}, {may}and "
                                          f"levels below {src.level}. Rule: {src.rule}"))
    return out


def test_the_table_is_read():
    """The table has its rows, and every row's parts named under "also imports" exist."""
    parts = layer_table()
    names = {p.name for p in parts}
    assert {"train", "bench", "experiments", "reports", "compare", "conform", "stress", "validate", "measurement",
            "plugins", "rasterizer", "model", "foundation", "oracle"} <= names, names
    assert all(a in names for p in parts for a in p.also), [(p.name, p.also) for p in parts]


def test_every_module_has_a_row():
    parts = layer_table()
    homeless = [m for m in module_names() if part_of(m, parts) is None]
    assert not homeless, f"modules on no row of {ARCHITECTURE.name} (add them to the table): {homeless}"


def test_every_import_follows_the_layer_table():
    found = [msg for module, target, msg in violations() if (module, target) not in KNOWN_EXCEPTIONS]
    assert not found, f"imports against the table in {ARCHITECTURE.name}:\n  " + "\n  ".join(found)


def test_known_exceptions_still_occur():
    found = {(module, target) for module, target, _ in violations()}
    gone = [pair for pair in KNOWN_EXCEPTIONS if pair not in found]
    assert not gone, f"these exceptions no longer occur: remove them from KNOWN_EXCEPTIONS: {gone}"


@pytest.mark.parametrize("importer, imported", [
    ("experiments", "reports"),   # a run kind declares its report as data
    ("train", "bench"),           # training measures with splatbench.metrics
    ("compare", "train"), ("compare", "experiments"), ("compare", "reports"),
    ("conform", "train"), ("conform", "experiments"), ("conform", "reports"),
    ("stress", "train"), ("stress", "experiments"), ("stress", "reports"),
    ("validate", "train"), ("validate", "experiments"), ("validate", "reports"),
    # the verification applications are siblings: they share only lower levels
    ("compare", "conform"), ("conform", "compare"), ("stress", "conform"), ("validate", "compare"),
    # the plugin interface is below every application that calls it
    ("plugins", "compare"), ("plugins", "conform"),
])
def test_no_import_from(importer, imported):
    """The issue's must-show pairs, named: no module of ``importer`` imports ``imported``."""
    parts = {p.name: p for p in layer_table()}
    assert not allowed(parts[importer], parts[imported]), "the table itself allows it"
    table = layer_table()
    modules = module_names()
    found = [f"{name} -> {imp.target} (line {imp.line})" for name, path in modules.items()
             if part_of(name, table) is parts[importer]
             for imp in import_edges(name, path, modules) if part_of(imp.target, table) is parts[imported]]
    assert not found, found


def test_the_checker_sees_a_break(tmp_path):
    """The checker itself: a late import against the table, one under TYPE_CHECKING, one in a
    ``__main__`` block (the entry layer: allowed) and modules named by strings on a small table."""
    pkg = tmp_path / PACKAGE
    (pkg / "low").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "low" / "__init__.py").write_text("")
    (pkg / "top.py").write_text("")
    (pkg / "low" / "a.py").write_text("def f():\n    from splatbench import high\n")
    (pkg / "low" / "b.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import splatbench.high\n")
    (pkg / "low" / "c.py").write_text("if __name__ == '__main__':\n    from splatbench import top\n")
    (pkg / "high.py").write_text("from splatbench.low import a\n")
    # a lazy export by string (as the package facade's `_LAZY` was, to splatbench.raster), a
    # registry entry, and strings that only look like module names (a custom op's name, prose)
    (pkg / "low" / "d.py").write_text('LAZY = {"thing": "splatbench.high"}\n'
                                      'COMMANDS = {"go": "splatbench.top:go"}\n'
                                      'NAME = "splatbench.composite"\nDOC = "see splatbench.high for more"\n')
    doc = tmp_path / "arch.md"
    doc.write_text("| Level | Part | Modules | Also imports | Rule |\n|---|---|---|---|---|\n"
                   "| 3 | top | `splatbench.top` | | anything |\n"
                   "| 2 | high | `splatbench.high` | | above low |\n"
                   "| 1 | low | `splatbench`, `splatbench.low` | | nothing above |\n")
    found = sorted((m, t) for m, t, _ in violations(pkg, doc))
    assert found == [("splatbench.low.a", "splatbench.high"), ("splatbench.low.b", "splatbench.high"),
                     ("splatbench.low.d", "splatbench.high"), ("splatbench.low.d", "splatbench.top")]
    assert "splatbench.low.d" not in import_graph(pkg)["splatbench.high"] and \
        import_graph(pkg)["splatbench.low.d"] == set()  # string edges are layer edges, not cycle edges
    message = violations(pkg, doc)[0][2]
    assert message.startswith("splatbench/low/a.py:2 imports splatbench.high (high, level 2)") and \
        message.endswith("Rule: nothing above")


def test_one_class_named_backend():
    """``Backend`` is the rasterizer plugin of splatbench.backends, nothing else."""
    found = [f"{path.relative_to(ROOT.parent)}:{node.lineno}" for path in sorted(ROOT.rglob("*.py"))
             for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
             if isinstance(node, ast.ClassDef) and node.name == "Backend"]
    assert len(found) == 1 and found[0].startswith("splatbench/backends/base.py:"), found


if __name__ == "__main__":  # `python tests/test_imports.py` lists the cycles
    g = import_graph()
    for comp in cycles(g):
        print(_example(comp, g), "  [", ", ".join(comp), "]")
    raise SystemExit(pytest.main([__file__, "-q"]))
