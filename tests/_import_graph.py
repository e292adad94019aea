"""The import graph of a package, read from its source with :mod:`ast` (nothing is imported).

Every ``import`` and ``from ... import`` statement counts: at module level, inside functions
and classes, and under ``if TYPE_CHECKING:`` (flagged, since it never runs). A name imported
from a package resolves to the submodule when one of that name exists, else to the package's
``__init__``. Run as a script to print the circles and the floors' breaks of a source tree::

    python tests/_import_graph.py src/vibrofocus
"""

from __future__ import annotations

import ast
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Edge:
    """One import statement's target inside the package."""

    importer: str  # dotted module name, e.g. "vibrofocus.io.calibration_nc"
    imported: str
    path: Path
    line: int
    in_function: bool
    type_checking: bool

    def __str__(self) -> str:
        where = "type-checking" if self.type_checking else "function" if self.in_function else "module"
        return f"{self.importer} -> {self.imported} ({self.path.name}:{self.line}, {where} level)"


def _modules(root: Path) -> dict[str, Path]:
    """Dotted name -> file for every module under the package folder ``root``."""
    found = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        found[".".join(parts)] = path
    return found


class _Visitor(ast.NodeVisitor):
    def __init__(self, name: str, path: Path, is_package: bool, modules: dict[str, Path]):
        self.name, self.path, self.modules = name, path, modules
        self.package = name if is_package else name.rpartition(".")[0]
        self.root = name.split(".")[0]
        self.depth = 0
        self.type_checking = 0
        self.edges: list[Edge] = []

    def _add(self, target: str, node: ast.stmt) -> None:
        # The longest prefix of the target that is a module of the package.
        while target and target not in self.modules:
            target = target.rpartition(".")[0]
        if target and target != self.name:
            self.edges.append(Edge(self.name, target, self.path, node.lineno, self.depth > 0, self.type_checking > 0))

    def visit_Import(self, node: ast.Import) -> None:
        for alias in node.names:
            if alias.name.split(".")[0] == self.root:
                self._add(alias.name, node)

    def visit_ImportFrom(self, node: ast.ImportFrom) -> None:
        if node.level:
            base = self.package.split(".")
            base = base[: len(base) - (node.level - 1)]
            module = ".".join(base + ([node.module] if node.module else []))
        else:
            module = node.module or ""
        if module.split(".")[0] != self.root:
            return
        for alias in node.names:
            sub = f"{module}.{alias.name}"
            self._add(sub if sub in self.modules else module, node)

    def _nested(self, node: ast.AST) -> None:
        self.depth += 1
        self.generic_visit(node)
        self.depth -= 1

    visit_FunctionDef = visit_AsyncFunctionDef = visit_Lambda = _nested

    def visit_If(self, node: ast.If) -> None:
        test = ast.unparse(node.test)
        if test in ("TYPE_CHECKING", "typing.TYPE_CHECKING"):
            self.type_checking += 1
            for child in node.body:
                self.visit(child)
            self.type_checking -= 1
            for child in node.orelse:
                self.visit(child)
        else:
            self.generic_visit(node)


def import_edges(root: str | Path) -> list[Edge]:
    """Every import inside the package whose folder is ``root``, in file and line order."""
    root = Path(root)
    modules = _modules(root)
    edges: list[Edge] = []
    for name, path in modules.items():
        visitor = _Visitor(name, path, path.name == "__init__.py", modules)
        visitor.visit(ast.parse(path.read_text(encoding="utf-8"), filename=str(path)))
        edges += visitor.edges
    return list(dict.fromkeys(edges))  # one edge per statement, not per imported name


def circles(edges: Iterable[Edge]) -> list[list[str]]:
    """The import circles: strongly connected groups of two or more modules (Tarjan).

    Imports that only run under ``TYPE_CHECKING`` do not count. A package's ``__init__``
    importing its own submodules is no circle unless a submodule imports the ``__init__``.
    """
    graph: dict[str, set[str]] = {}
    for edge in edges:
        if not edge.type_checking:
            graph.setdefault(edge.importer, set()).add(edge.imported)
            graph.setdefault(edge.imported, set())
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    groups: list[list[str]] = []

    def connect(node: str) -> None:  # recursion depth <= the number of modules
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph[node]):
            if nxt not in index:
                connect(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            group = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                group.append(member)
                if member == node:
                    break
            if len(group) > 1:
                groups.append(sorted(group))

    for node in sorted(graph):
        if node not in index:
            connect(node)
    return sorted(groups)


def unit(module: str, floors: Sequence[Sequence[str]]) -> str:
    """The top-level unit (subpackage or module) of a dotted module name, e.g. ``io``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def floor_of(module: str, floors: Sequence[Sequence[str]]) -> int | None:
    """The index of the floor that holds ``module``'s unit; None for the top package itself."""
    name = unit(module, floors)
    for level, units in enumerate(floors):
        if name in units:
            return level
    if name == "":
        return None
    raise KeyError(f"{module}: its unit {name!r} is on no floor")


def layering_breaks(edges: Iterable[Edge], floors: Sequence[Sequence[str]]) -> list[Edge]:
    """The imports that go up a floor or sideways to another unit on the same floor.

    ``floors`` lists the package's units (subpackages and top-level modules) from the bottom
    up; a module may import its own unit and every unit on a lower floor. Imports under
    ``TYPE_CHECKING`` count too: a type is a dependency even where it never runs.
    """
    breaks = []
    for edge in edges:
        mine, theirs = floor_of(edge.importer, floors), floor_of(edge.imported, floors)
        if mine is None or theirs is None or unit(edge.importer, floors) == unit(edge.imported, floors):
            continue
        if theirs >= mine:
            breaks.append(edge)
    return breaks


def _main(argv: list[str]) -> int:
    root = Path(argv[0] if argv else "src/vibrofocus")
    edges = import_edges(root)
    found = circles(edges)
    print(f"{len(edges)} imports inside the package "
          f"({sum(e.in_function and not e.type_checking for e in edges)} inside functions, "
          f"{sum(e.type_checking for e in edges)} under TYPE_CHECKING)")
    print(f"{len(found)} import circle(s), counting imports inside functions:")
    for group in found:
        print("  " + "  ".join(group))
        inside = {m for m in group}
        for edge in edges:
            if edge.importer in inside and edge.imported in inside and not edge.type_checking:
                print(f"      {edge}")
    found_module_level = circles(e for e in edges if not e.in_function)
    print(f"{len(found_module_level)} import circle(s) at module level only")
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
