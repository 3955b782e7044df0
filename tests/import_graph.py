"""The import graph of the distribution's packages and their modules, and its checks.

Run ``python -m tests.import_graph`` to print it: the packages lowest layer
first, each with the packages it imports, then every module with the modules
it imports.  Every ``import`` statement counts -- at the top of a module,
inside a function (a lazy import), under ``if TYPE_CHECKING:`` -- because each
is a dependency a reader must know about.  (Registries name entries as
``"module:attribute"`` strings loaded on first use; those are not imports.)
``tests/test_layers.py`` asserts what this prints at its end: no cycle among
the modules, and no import of a higher layer by a lower one.
"""

from __future__ import annotations

import ast
import sys
from collections import defaultdict
from collections.abc import Iterator
from pathlib import Path

__all__ = [
    "LAYERS",
    "ROOT",
    "SUBLAYERS",
    "cycles",
    "module_graph",
    "package_graph",
    "sublayer_upward_edges",
    "upward_edges",
]

ROOT = Path(__file__).resolve().parents[1]
#: The top-level packages, lowest layer first: each may import only those before it.
LAYERS = (
    "rocketroll_common",
    "rocketroll_physics",
    "identification",
    "disturbances",
    "rollenv",
    "agents",
    "rocketroll",
)
#: A package's sub-packages and top-level modules, lowest layer first: each may import only
#: those before it (the package's ``__init__`` may import any).
SUBLAYERS = {
    "identification": (
        "paper",
        "model",
        "compiled",
        "recordings",
        "instruments",
        "estimation",
        "methods",
        "reports",
        "cli",
    ),
}


def _modules() -> dict[str, Path]:
    found = {}
    for package in LAYERS:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            found[name] = path
    return found


def _imported(node: ast.AST, module: str, modules: dict[str, Path]) -> Iterator[str]:
    """The distribution's modules one import statement names."""
    if isinstance(node, ast.Import):
        names = [alias.name for alias in node.names]
    elif isinstance(node, ast.ImportFrom):
        base = node.module or ""
        if node.level:  # relative: resolve against this module's package
            package = module if modules[module].name == "__init__.py" else module.rpartition(".")[0]
            for _ in range(node.level - 1):
                package = package.rpartition(".")[0]
            base = f"{package}.{base}" if base else package
        # ``from pkg import sub`` imports the module pkg.sub; ``from mod import name`` mod.
        names = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
    else:
        return
    for name in names:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        if name and name != module:
            yield name


def module_graph() -> dict[str, set[str]]:
    """Module -> the modules of the distribution it imports."""
    modules = _modules()
    graph: dict[str, set[str]] = {name: set() for name in modules}
    for name, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            graph[name].update(_imported(node, name, modules))
    return graph


#: Private names another module may import, and why.
PRIVATE_IMPORTS_ALLOWED = {
    # Committed model zips pickled the learning-rate schedule as agents.train._LinearSchedule
    # (agents.train was one module then): the name must stay where those files look for it.
    ("agents.train", "agents.train.hyperparams", "_LinearSchedule"),
}


def private_imports() -> list[tuple[str, str, str]]:
    """(importer, module, name) for each private name (``_x``, not ``__x__``) one module of
    the distribution imports from another, less :data:`PRIVATE_IMPORTS_ALLOWED`."""
    modules = _modules()
    found = []
    for name, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ImportFrom) or node.level or node.module not in modules:
                continue
            for alias in node.names:
                private = alias.name.startswith("_") and not alias.name.startswith("__")
                if private and node.module != name:
                    found.append((name, node.module, alias.name))
    return sorted(set(found) - PRIVATE_IMPORTS_ALLOWED)


def package_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """Top-level package -> the other top-level packages its modules import."""
    packages: dict[str, set[str]] = defaultdict(set)
    for module, targets in graph.items():
        top = module.split(".")[0]
        packages[top].update(t.split(".")[0] for t in targets if t.split(".")[0] != top)
    return {p: packages[p] for p in LAYERS}


def upward_edges(graph: dict[str, set[str]]) -> list[tuple[str, str]]:
    """``(module, imported module)`` where a lower layer imports a higher one."""
    rank = {p: i for i, p in enumerate(LAYERS)}
    return sorted(
        (m, t)
        for m, targets in graph.items()
        for t in targets
        if rank[t.split(".")[0]] > rank[m.split(".")[0]]
    )


def sublayer_upward_edges(graph: dict[str, set[str]]) -> list[tuple[str, str]]:
    """``(module, imported module)`` where, inside a package of :data:`SUBLAYERS`, a lower
    sub-package imports a higher one."""
    found = []
    for package, order in SUBLAYERS.items():

        def rank(module: str, package: str = package, order: tuple[str, ...] = order) -> int:
            parts = module.split(".")
            return order.index(parts[1]) if parts[0] == package and len(parts) > 1 else -1

        found += [
            (m, t)
            for m, targets in graph.items()
            if rank(m) >= 0
            for t in targets
            if rank(t) > rank(m)
        ]
    return sorted(found)


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Every cycle found by a depth-first search (empty: the graph is acyclic)."""
    found: list[list[str]] = []
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> None:
        state[node] = 1
        stack.append(node)
        for target in sorted(graph[node]):
            if state.get(target) == 1:
                found.append([*stack[stack.index(target) :], target])
            elif target not in state:
                visit(target)
        stack.pop()
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node)
    return found


def main() -> int:
    """Print the graph and the verdict; exit code 1 if there is a cycle or an upward edge."""
    graph = module_graph()
    packages = package_graph(graph)
    print("packages, lowest layer first (each imports only layers before it):")
    for package in LAYERS:
        print(f"  {package:<18} -> {', '.join(sorted(packages[package], key=LAYERS.index)) or '-'}")
    print("\nmodules:")
    for module in sorted(graph, key=lambda m: (LAYERS.index(m.split(".")[0]), m)):
        print(f"  {module:<34} -> {', '.join(sorted(graph[module])) or '-'}")
    found, upward = cycles(graph), upward_edges(graph) + sublayer_upward_edges(graph)
    for cycle in found:
        print(f"CYCLE: {' -> '.join(cycle)}")
    for low, high in upward:
        print(f"UPWARD: {low} -> {high}")
    edges = sum(len(t) for t in graph.values())
    print(
        f"\n{len(graph)} modules, {edges} import edges: {len(found)} cycles, "
        f"{len(upward)} upward edges"
    )
    return 1 if found or upward else 0


if __name__ == "__main__":
    sys.exit(main())
