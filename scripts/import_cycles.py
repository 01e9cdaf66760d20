"""Import cycles between the packages of hubsgo_ppl and between its modules.

Every ``import`` and ``from ... import`` in ``hubsgo_ppl/**.py`` counts, wherever it stands: at module
level, inside a function, or under ``if TYPE_CHECKING``. At package level each module belongs to
``hubsgo_ppl.<first name>`` (a subpackage such as ``hubsgo_ppl.infer`` or a top-level module such as
``hubsgo_ppl.specs``); imports within one package are ignored there, and counted between its modules
(``agents.config`` -> ``agents.hiro`` -> ``agents.config`` is a module cycle). A cycle is a strongly
connected component of two or more nodes.

    python scripts/import_cycles.py            # the package graph, package and module cycles; exit 1 on any
    python scripts/import_cycles.py --json     # {"edges": ..., "cycles": ..., "module_cycles": ...}
"""

from __future__ import annotations

import argparse
import ast
import json
import sys
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "hubsgo_ppl"


def module_names(root: Path = ROOT, package: str = PACKAGE) -> dict[str, Path]:
    """``{dotted module name: file}`` for every module of ``package`` (``pkg/__init__.py`` is ``pkg``)."""
    out = {}
    for path in sorted((root / package).rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The package's modules that ``name`` (the module in ``path``) imports, anywhere in its body."""
    is_package = path.name == "__init__.py"
    here = name.split(".") if is_package else name.split(".")[:-1]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = here[: len(here) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            # `from pkg import name` imports the submodule pkg.name when there is one, else pkg itself
            targets = [f"{target}.{a.name}" if f"{target}.{a.name}" in modules else target for a in node.names]
        else:
            continue
        for target in targets:
            while target and target not in modules:      # `import a.b.c` of a non-module: its package
                target = target.rpartition(".")[0]
            if target and target != name:
                found.add(target)
    return found


def module_graph(root: Path = ROOT, package: str = PACKAGE) -> dict[str, set[str]]:
    modules = module_names(root, package)
    return {name: _imports(name, path, modules) for name, path in modules.items()}


def package_of(module: str) -> str:
    """``hubsgo_ppl.<first name>``, or ``hubsgo_ppl`` for the package's own ``__init__``."""
    return ".".join(module.split(".")[:2])


def package_graph(modules: dict[str, set[str]]) -> dict[str, set[str]]:
    graph: dict[str, set[str]] = defaultdict(set)
    for src, targets in modules.items():
        graph[package_of(src)]
        for dst in targets:
            if package_of(dst) != package_of(src):
                graph[package_of(src)].add(package_of(dst))
    return dict(graph)


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with two or more nodes (Tarjan), each sorted, in sorted order."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

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
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(found)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    args = parser.parse_args(argv)
    modules = module_graph()
    packages = package_graph(modules)
    found = cycles(packages)
    module_cycles = cycles(modules)
    if args.json:
        print(json.dumps({"edges": {k: sorted(v) for k, v in sorted(packages.items())}, "cycles": found,
                          "module_cycles": module_cycles}, indent=1))
        return 1 if found or module_cycles else 0
    print(f"{len(packages)} packages, {sum(map(len, packages.values()))} import edges between them")
    for src in sorted(packages):
        print(f"  {src} -> {', '.join(sorted(packages[src])) or '(nothing)'}")
    print(f"package cycles: {len(found)}")
    for c in found:
        print("  " + " <-> ".join(c))
    print(f"module cycles: {len(module_cycles)}")
    for c in module_cycles:
        print("  " + " <-> ".join(c))
    return 1 if found or module_cycles else 0


if __name__ == "__main__":
    sys.exit(main())
