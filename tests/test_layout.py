"""The package layout: no import loop, small modules, thin commands.

Run as a script to print the module graph (``python tests/test_layout.py``): one line per module
with the package modules it imports (at module level or inside functions).
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "o3d_seqcc"
MAX_LINES = 620


def _module_name(path: Path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _parents(name: str) -> list[str]:
    """``o3d_seqcc.a.b`` -> ``["o3d_seqcc.a", "o3d_seqcc.a.b"]``: importing a module runs its packages' ``__init__``."""
    parts = name.split(".")
    return [".".join(parts[:k]) for k in range(2, len(parts) + 1)]


def module_graph() -> dict[str, set[str]]:
    """Module -> package modules it imports (relative and absolute imports, any nesting level)."""
    modules = {_module_name(p): p for p in PKG.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        is_pkg = path.name == "__init__.py"
        base = name.split(".") if is_pkg else name.split(".")[:-1]
        deps: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets: list[str] = []
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    root = ".".join(base[: len(base) - node.level + 1] + ([node.module] if node.module else []))
                else:
                    root = node.module or ""
                targets = [root] + [f"{root}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            for t in targets:
                if t in modules:
                    # the packages that hold the importer itself are already being imported: not an edge
                    deps.update(p for p in _parents(t) if not (name == p or name.startswith(p + ".")))
        deps.discard(name)
        graph[name] = {d for d in deps if d in modules and d != "o3d_seqcc"}
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """A cycle of the graph as a list of modules, or None (iterative depth-first search)."""
    state: dict[str, int] = {}
    for start in sorted(graph):
        if state.get(start):
            continue
        stack = [(start, iter(sorted(graph[start])))]
        path = [start]
        state[start] = 1
        while stack:
            node, it = stack[-1]
            nxt = next(it, None)
            if nxt is None:
                state[node] = 2
                stack.pop()
                path.pop()
            elif state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            elif not state.get(nxt):
                state[nxt] = 1
                stack.append((nxt, iter(sorted(graph.get(nxt, ())))))
                path.append(nxt)
    return None


def test_no_import_loop():
    graph = module_graph()
    assert len(graph) > 30
    assert find_cycle(graph) is None, f"import loop: {' -> '.join(find_cycle(graph))}"


def test_cycle_finder_finds_a_planted_loop():
    graph = module_graph()
    graph["o3d_seqcc.errors"] = graph["o3d_seqcc.errors"] | {"o3d_seqcc.pipeline"}
    cycle = find_cycle(graph)
    assert cycle is not None and cycle[0] == cycle[-1]


def test_modules_are_small():
    sizes = {p.relative_to(PKG.parent).as_posix(): len(p.read_text().splitlines()) for p in PKG.rglob("*.py")}
    big = {k: n for k, n in sizes.items() if n > MAX_LINES}
    assert not big, f"modules over {MAX_LINES} lines: {big}"


def test_library_does_not_import_the_cli():
    graph = module_graph()
    offenders = sorted(m for m, deps in graph.items() if not m.startswith(("o3d_seqcc.cli", "o3d_seqcc.__main__"))
                       and any(d.startswith("o3d_seqcc.cli") for d in deps))
    assert not offenders, offenders


def test_library_code_does_not_print_or_exit():
    bad = []
    for p in PKG.rglob("*.py"):
        if "cli" in p.relative_to(PKG).parts or p.name == "__main__.py":
            continue
        for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "print":
                bad.append(f"{p.name}:{node.lineno} print")
            if isinstance(node, ast.Attribute) and node.attr == "exit" and getattr(node.value, "id", "") == "sys":
                bad.append(f"{p.name}:{node.lineno} sys.exit")
            if isinstance(node, ast.ExceptHandler) and isinstance(node.type, ast.Name) and node.type.id == "ImportError":
                bad.append(f"{p.name}:{node.lineno} except ImportError")
    assert not bad, bad


if __name__ == "__main__":  # pragma: no cover - prints the graph for docs/ARCHITECTURE.md
    g = module_graph()
    for m in sorted(g):
        short = sorted(d.removeprefix("o3d_seqcc.") for d in g[m])
        print(f"{m.removeprefix('o3d_seqcc.') or 'o3d_seqcc'}: {', '.join(short) or '-'}")
    sys.exit(1 if find_cycle(g) else 0)
