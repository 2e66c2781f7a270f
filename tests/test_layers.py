"""The package's layering (docs/design.md, "Layers"): no module imports, at run time, one of a
higher floor, and no two modules import each other in a circle.

Why a test: the real-data work grew the package fast and three circles and a dozen upward
imports crept in unseen. An AST walk over ``core/`` finds every import a module runs (at
module level or inside a function; ``if TYPE_CHECKING:`` blocks are not run and not counted).
"""

import ast
import pathlib

CORE = pathlib.Path(__file__).resolve().parents[1] / "core"

# Floors, lowest first: a package may import its own floor's packages and any lower floor's.
FLOORS: list[set[str]] = [
    {"errors", "lazy"},
    {"hookspecs", "formats", "registry"},       # the plugin door: joint types, readers, solvers by name
    {"numeric"},
    {"model"},
    {"kinematics"},
    {"dynamics"},
    {"solvers", "io"},
    {"recordings"},                             # logs -> measured data
    {"identify"},                               # fitting
    {"diagnose", "orchestrate"},                # what a model lacks; validate's jobs and runners
    {"excite"},
    {"api"},
    {"cli", "__main__"},
]
FLOOR = {package: level for level, packages in enumerate(FLOORS) for package in packages}


def _module_name(path: pathlib.Path) -> str:
    parts = list(path.relative_to(CORE).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(["baseparams", *parts])


def _runtime_imports(tree: ast.AST, package: str = "baseparams") -> list[tuple[str, int]]:
    """(imported module or name, line) of every import the module runs; relative imports
    resolved against ``package`` (the module's own package)."""
    found: list[tuple[str, int]] = []

    class Visitor(ast.NodeVisitor):
        def visit_If(self, node: ast.If) -> None:
            test = node.test
            if (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or \
                    (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"):
                for statement in node.orelse:
                    self.visit(statement)
                return
            self.generic_visit(node)

        def visit_Import(self, node: ast.Import) -> None:
            found.extend((alias.name, node.lineno) for alias in node.names)

        def visit_ImportFrom(self, node: ast.ImportFrom) -> None:
            module = node.module or ""
            if node.level:
                parts = package.split(".")
                anchor = ".".join(parts[:len(parts) - node.level + 1])
                module = f"{anchor}.{module}" if module else anchor
            if module:
                found.append((module, node.lineno))
                found.extend((f"{module}.{alias.name}", node.lineno) for alias in node.names)

    Visitor().visit(tree)
    return found


def _graph() -> dict[str, dict[str, int]]:
    """module -> {imported baseparams module: line}."""
    modules = {_module_name(path): path for path in CORE.rglob("*.py")}
    graph: dict[str, dict[str, int]] = {}
    for name, path in modules.items():
        edges: dict[str, int] = {}
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for target, line in _runtime_imports(ast.parse(path.read_text(), str(path)), package):
            if target in modules and target not in (name, "baseparams"):
                edges.setdefault(target, line)
        graph[name] = edges
    return graph


def _package(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def test_every_package_has_a_floor():
    packages = {_package(m) for m in _graph()} - {""}
    assert packages <= set(FLOOR), f"packages without a floor in this test and docs/design.md: {packages - set(FLOOR)}"


def test_no_import_from_a_higher_floor():
    upward = [f"{source} (line {line}) imports {target}"
              for source, edges in _graph().items() if _package(source)
              for target, line in edges.items()
              if FLOOR[_package(target)] > FLOOR[_package(source)]]
    assert not upward, "imports from a higher floor at run time:\n" + "\n".join(sorted(upward))


def test_no_import_circle():
    graph = _graph()
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    circles: list[list[str]] = []

    def strongly_connected(v: str) -> None:        # Tarjan
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                strongly_connected(w)
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
                circles.append(sorted(component))

    for module in graph:
        if module not in index:
            strongly_connected(module)
    assert not circles, f"import circles: {circles}"


def test_the_walk_sees_upward_and_circular_imports(tmp_path):
    """The checks can fail: a function-level import counts, a TYPE_CHECKING one does not, a
    relative one is resolved."""
    tree = ast.parse("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from baseparams.cli import x\n"
                     "def f():\n    from baseparams.api.data import y\n    from .results import Z\n"
                     "    from .. import errors\n")
    found = [name for name, _ in _runtime_imports(tree, "baseparams.api")]
    assert "baseparams.api.data" in found and "baseparams.cli" not in found
    assert "baseparams.api.results" in found and "baseparams.errors" in found
