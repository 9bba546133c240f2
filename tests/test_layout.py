"""The package layout: the tree of stage packages, one-way imports, small modules, thin commands.

Run as a script to print the module graph (``python tests/test_layout.py``): one line per module
with the package modules it imports (at module level or inside functions).
"""

from __future__ import annotations

import ast
import functools
import re
import sys
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "o3d_seqcc"
MAX_LINES = 620
#: a command module (``cli/<command>.py``) parses, calls the library and prints: at most this many lines
MAX_COMMAND_LINES = 250
ARCHITECTURE = PKG.parent / "docs" / "ARCHITECTURE.md"

#: the tree: package -> its modules ("" is the top level). A new module goes here and into
#: docs/ARCHITECTURE.md's drawing, in the stage it belongs to.
TREE: dict[str, set[str]] = {
    "": {"__init__", "__main__", "errors", "scene", "settings", "pipeline", "open3d_api", "demo", "datasets"},
    "_shared": {"__init__", "arguments", "interrupts", "lazy", "numbers", "options", "parallel", "progress", "registry",
                "sets"},
    "imaging": {"__init__", "arrays", "sequences"},
    "geometry": {"__init__", "camera", "distortion", "meshops", "meshsplit", "orientation"},
    "visibility": {"__init__", "settings", "dense", "camera_checks", "depthmaps", "occlusion", "per_view", "refine", "stray",
                   "compute", "subpixel", "masks"},
    "mappings": {"__init__", "pairs", "counting", "sampling", "compute"},
    "correction": {"__init__", "settings", "base", "graph", "jih", "cmf", "luts"},
    "correction.methods": {"__init__", "seqcc", "seqcc_global", "edge_summaries", "joint_curves", "curve_adjust",
                           "value_space",
                           "pairwise", "global_methods"},
    "texturing": {"__init__", "settings", "selection", "data_costs", "outliers", "charts", "packing", "packing_child", "bake", "fill",
                  "atlas", "fallback", "leveling", "textured_mesh", "memory", "own_uv", "blocks"},
    "evaluation": {"__init__", "metrics", "table2", "fit", "photometric", "semireal", "seams", "sharpness", "render"},
    "io": {"__init__", "regular_files", "atomic", "raster_checks", "images", "depth", "json_files", "paths", "headers",
           "mesh_files", "missing", "load", "scene_json", "meshlab", "meshroom", "rgbd_folder",
           "colmap", "openmvs", "nvm", "metashape", "mve", "bundler", "mappings_npz", "output", "manifest",
           "gltf_validator", "masks"},
    "io.export": {"__init__", "common", "textures", "obj", "obj_text", "glb", "ply", "meshlab_ply"},
    "report": {"__init__", "schema", "page", "parts", "viewer", "comparison", "figures", "html", "validate", "background", "masks",
               "style", "inputs", "table2"},
    "run_folder": {"__init__", "layout", "write", "parts", "read"},
    "synthetic": {"__init__", "room", "generate", "occluder"},
    "cli": {"__init__", "parser", "console", "runtime", "scene_flags", "correction_flags", "texture_flags",
            "run", "texture", "correct", "mappings", "evaluate", "seams", "report", "info", "demo", "synthetic"},
}
#: at most this many modules at the top level, besides the package's __init__ and __main__
MAX_TOP_LEVEL = 8

#: the layers, bottom up: a module imports only from its own layer and the layers below (the pipeline's
#: one-way flow). io's file layer (regular_files, atomic, raster_checks, images, depth, json_files, paths,
#: headers, mesh_files, masks, missing) sits at the bottom, used by the scene model and the image sequences; its formats (readers and writers) sit above the stages whose objects they write.
LAYERS: list[tuple[str, ...]] = [
    ("errors",),
    ("_shared", "io.regular_files", "io.atomic", "io.raster_checks", "io.images", "io.depth", "io.json_files",
     "io.paths", "io.headers", "io.mesh_files", "io.masks", "io.missing"),
    ("imaging",),
    ("geometry",),
    ("scene",),
    ("visibility",),
    ("mappings",),
    ("correction",),
    ("texturing",),
    ("evaluation",),
    ("io", "run_folder.layout"),
    ("report",),
    ("synthetic", "datasets", "settings"),
    ("pipeline", "run_folder"),
    ("open3d_api", "demo"),
    ("cli", "__main__"),
]


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


def _import_root(node: ast.ImportFrom, base: list[str]) -> str:
    """The absolute module an ``from X import ...`` names, for a module in the package ``base`` (a list of names)."""
    if node.level:
        return ".".join(base[: len(base) - node.level + 1] + ([node.module] if node.module else []))
    return node.module or ""


def _import_nodes():
    """(module name, its package as a list of names, import node) for every import in the package, at any depth."""
    for path in PKG.rglob("*.py"):
        name = _module_name(path)
        base = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                yield name, base, node


def module_graph() -> dict[str, set[str]]:
    """Module -> package modules it imports (relative and absolute imports, any nesting level)."""
    modules = {_module_name(p): p for p in PKG.rglob("*.py")}
    graph: dict[str, set[str]] = {name: set() for name in modules}
    for name, base, node in _import_nodes():
        if isinstance(node, ast.ImportFrom):
            root = _import_root(node, base)
            targets = [root] + [f"{root}.{a.name}" for a in node.names]
        else:
            targets = [a.name for a in node.names]
        for t in targets:
            if t in modules:
                # the packages that hold the importer itself are already being imported: not an edge
                graph[name].update(p for p in _parents(t) if not (name == p or name.startswith(p + ".")))
    return {name: {d for d in deps if d in modules and d not in ("o3d_seqcc", name)} for name, deps in graph.items()}


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


def test_commands_are_thin():
    """Each command's module (``cli/<command>.py``) is at most :data:`MAX_COMMAND_LINES` lines: what several
    commands share lives in the CLI's other modules (the parser, the console, the runtime, the flags)."""
    from o3d_seqcc.cli import COMMANDS

    assert set(COMMANDS) <= TREE["cli"], sorted(set(COMMANDS) - TREE["cli"])
    sizes = {c: len((PKG / "cli" / f"{c}.py").read_text(encoding="utf-8").splitlines()) for c in COMMANDS}
    fat = {f"cli/{c}.py": n for c, n in sizes.items() if n > MAX_COMMAND_LINES}
    assert not fat, f"command modules over {MAX_COMMAND_LINES} lines: {fat}"


def _tree_on_disk() -> dict[str, set[str]]:
    tree: dict[str, set[str]] = {}
    for p in PKG.rglob("*.py"):
        rel = p.relative_to(PKG).with_suffix("")
        tree.setdefault(".".join(rel.parts[:-1]), set()).add(rel.parts[-1])
    return tree


def test_tree_is_the_documented_one():
    on_disk = _tree_on_disk()
    extra = {f"{k}.{m}".strip("."): None for k, ms in on_disk.items() for m in ms - TREE.get(k, set())}
    missing = {f"{k}.{m}".strip("."): None for k, ms in TREE.items() for m in ms - on_disk.get(k, set())}
    assert not extra and not missing, f"modules not in TREE: {sorted(extra)}; in TREE but absent: {sorted(missing)}"


def test_top_level_is_small():
    top = TREE[""] - {"__init__", "__main__"}
    assert len(top) <= MAX_TOP_LEVEL, sorted(top)
    assert {"errors", "scene", "pipeline", "open3d_api"} <= top


def test_architecture_draws_the_tree():
    """docs/ARCHITECTURE.md's layout block names every package and module of the tree."""
    text = ARCHITECTURE.read_text(encoding="utf-8")
    block = text[text.index("```text"):]
    block = block[: block.index("```", 3)]
    for pkg, modules in TREE.items():
        if pkg:
            assert re.search(rf"^\s*{re.escape(pkg.split('.')[-1])}/", block, re.M), f"{pkg}/ not drawn"
        for m in modules - {"__init__", "__main__"}:
            assert re.search(rf"(^|\s){re.escape(m)}\.py\b", block, re.M), f"{pkg or 'o3d_seqcc'}.{m} not drawn"


def layer_of(module: str) -> int:
    """The index in :data:`LAYERS` of a module (``o3d_seqcc.x.y``): its longest matching prefix."""
    rel = module.removeprefix("o3d_seqcc").lstrip(".")
    best, length = None, -1
    for i, layer in enumerate(LAYERS):
        for prefix in layer:
            if (rel == prefix or rel.startswith(prefix + ".")) and len(prefix) > length:
                best, length = i, len(prefix)
    if best is None:
        raise AssertionError(f"{module} is in no layer of LAYERS")
    return best


def direct_imports() -> dict[str, set[str]]:
    """Module -> the package modules it names in an import (no parent packages added).

    A parent package's ``__init__`` runs too, but every package ``__init__`` below the pipeline imports
    nothing of its own stage eagerly (lazy re-exports), so only the named module is a dependency.
    """
    modules = {_module_name(p): p for p in PKG.rglob("*.py")}
    out: dict[str, set[str]] = {name: set() for name in modules}
    for name, base, node in _import_nodes():
        if isinstance(node, ast.ImportFrom):
            root = _import_root(node, base)
            out[name].update(f"{root}.{a.name}" if f"{root}.{a.name}" in modules else root for a in node.names)
        else:
            out[name].update(a.name for a in node.names)
    return {name: {d for d in deps if d in modules and d not in ("o3d_seqcc", name)} for name, deps in out.items()}


def upward_imports(graph: dict[str, set[str]]) -> list[str]:
    return sorted(f"{m} -> {d}" for m, deps in graph.items() if m != "o3d_seqcc" for d in deps
                  if layer_of(d) > layer_of(m))


def test_imports_flow_one_way():
    graph = direct_imports()
    assert len(graph) > 60
    assert not upward_imports(graph), "imports against the pipeline's flow: " + "; ".join(upward_imports(graph))


def test_upward_import_is_caught():
    graph = direct_imports()
    graph["o3d_seqcc.visibility.compute"] = graph["o3d_seqcc.visibility.compute"] | {"o3d_seqcc.texturing.atlas"}
    assert upward_imports(graph) == ["o3d_seqcc.visibility.compute -> o3d_seqcc.texturing.atlas"]


def test_package_inits_import_no_stage_eagerly():
    """A stage package's ``__init__`` re-exports lazily (``_shared.lazy``), so importing one leaf module never
    runs its siblings (and the layers above stay out of the layers below)."""
    graph = direct_imports()
    eager = {pkg: sorted(graph[f"o3d_seqcc.{pkg}"] - {"o3d_seqcc._shared.lazy"})
             for pkg in ("_shared", "imaging", "geometry", "visibility", "mappings", "texturing", "evaluation", "io")}
    # (correction/methods/__init__.py is the literal method table: it imports its methods by design; so is
    # io/export/__init__.py, the format table of its writers)
    assert not any(eager.values()), eager


def test_no_private_names_across_packages():
    """``from ..other_stage.module import _private`` is an internal reaching across a stage boundary."""
    stage = lambda m: m.split(".")[1] if m.count(".") else ""  # noqa: E731
    bad = []
    for name, base, node in _import_nodes():
        if isinstance(node, ast.ImportFrom) and (node.level or (node.module or "").startswith("o3d_seqcc")):
            root = _import_root(node, base)
            bad += [f"{name}:{node.lineno} {root}.{a.name}" for a in node.names
                    if a.name.startswith("_") and not a.name.startswith("__") and stage(root) != stage(name)]
    assert not bad, bad


#: the stage packages: a name another part of the package imports from one of their modules is in the
#: package's public list (its ``__init__``'s ``__all__`` or lazy export table)
STAGE_PACKAGES = ("visibility", "mappings", "correction", "texturing", "evaluation", "io", "report", "imaging",
                  "geometry", "synthetic", "cli")
MESHLAB_FILTERS = PKG.parent / "meshlab_filters"


def public_names(package: str) -> set[str]:
    """The public list of a stage package: its ``__init__``'s ``__all__`` and the names of its
    :func:`~o3d_seqcc._shared.lazy.lazy_exports` table, read from the source (nothing imported)."""
    names: set[str] = set()
    for node in ast.parse((PKG / package / "__init__.py").read_text(encoding="utf-8")).body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in node.targets):
            names |= set(ast.literal_eval(node.value))
        call = getattr(node, "value", None)
        if isinstance(call, ast.Call) and getattr(call.func, "id", None) == "lazy_exports":
            table = call.args[1]
            for key, value in zip(table.keys, table.values):  # "name": "module" or **dict.fromkeys((names), "module")
                names |= {ast.literal_eval(key)} if key is not None else set(ast.literal_eval(value.args[0]))
    return names


@functools.cache
def _from_imports() -> tuple:
    """(module, its package, node) of every ``from ... import`` in the package (parsed once for all stages)."""
    return tuple(item for item in _import_nodes() if isinstance(item[2], ast.ImportFrom))


def internal_imports(package: str, imports=None) -> list[str]:
    """``module:line name`` of every ``from o3d_seqcc.<package>.<module> import name`` (or its relative
    equivalent) made outside ``package`` whose name is not in the package's :func:`public_names`
    (``imports``: the (module, package, node) triples to check, default the whole package's)."""
    public, prefix, bad = public_names(package), f"o3d_seqcc.{package}", []
    for name, base, node in _from_imports() if imports is None else imports:
        if name == prefix or name.startswith(prefix + "."):
            continue
        root = _import_root(node, base)
        if root.startswith(prefix + "."):
            bad += [f"{name}:{node.lineno} {root}.{a.name}" for a in node.names if a.name not in public]
    return bad


@pytest.mark.parametrize("package", STAGE_PACKAGES)
def test_stages_import_each_other_by_public_names(package):
    """One stage uses another's names only when that package lists them (its ``__init__``'s exports)."""
    bad = internal_imports(package)
    assert not bad, f"{len(bad)} names imported from {package}'s modules that {package} does not export: {bad}"


def test_an_internal_name_across_stages_is_caught():
    assert {"PairSource", "shared_counts", "before_after"} <= public_names("mappings") | public_names("evaluation")
    planted = [("o3d_seqcc.texturing.atlas", ["o3d_seqcc", "texturing"], ast.parse(src).body[0]) for src in (
        "from ..mappings.pairs import norm_key, thinned", "from o3d_seqcc.mappings.counting import shared_area",
        "from .charts import norm_key")]
    assert internal_imports("mappings", planted) == ["o3d_seqcc.texturing.atlas:1 o3d_seqcc.mappings.pairs.norm_key"]


def test_meshlab_filters_use_the_library_not_the_cli():
    """The MeshLab filters are a front door of the library: they import nothing from ``o3d_seqcc.cli``, except
    the native plugin's header builder, which describes the ``o3d-seqcc`` commands the plugin runs and reads
    their options from the command line's public parser (``o3d_seqcc.cli.build_parser``)."""
    bad = []
    for path in sorted(MESHLAB_FILTERS.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                base = ["meshlab_filters", *path.relative_to(MESHLAB_FILTERS).parent.parts]
                mods = [_import_root(node, base)]
                names = [a.name for a in node.names]
            elif isinstance(node, ast.Import):
                mods, names = [a.name for a in node.names], []
            else:
                continue
            for mod in mods:
                if mod == "o3d_seqcc.cli" and path.name == "native.py" and names == ["build_parser"]:
                    continue
                if mod == "o3d_seqcc.cli" or mod.startswith("o3d_seqcc.cli."):
                    bad.append(f"{path.relative_to(PKG.parent)}:{node.lineno} {mod} {names}")
    assert MESHLAB_FILTERS.is_dir() and not bad, bad


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


# ------------------------------------------------------------------------------------- the run folder
#: the packages whose code may name a run folder's files (the library and its MeshLab filters)
CODE = (PKG, PKG.parent / "meshlab_filters")
#: layout.py's names that are the run folder's alone ("scene.json", "mesh.ply" and "images" also name a scene's
#: own files, written by the scene formats and the synthetic scenes, not by a run)
RUN_NAMES = ("REPORT_JSON", "REPORT_HTML", "SELECTION_NPY", "SELECTION_PNG", "MESHLAB_LAYER", "MESHLAB_PROJECT",
             "DEMO_SUMMARY")


def _string_constants(tree: ast.AST) -> list[ast.Constant]:
    """The string literals of a module that are not docstrings (text for readers, not names the code uses)."""
    docs = {id(b.body[0].value) for b in ast.walk(tree)
            if isinstance(b, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and b.body
            and isinstance(b.body[0], ast.Expr) and isinstance(b.body[0].value, ast.Constant)}
    return [n for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docs]


def test_every_run_folder_name_is_spelled_in_layout_only():
    """A file name of the run folder is a string of its own in run_folder/layout.py only (messages and help texts
    that mention one are prose, not the name the code opens)."""
    from o3d_seqcc.run_folder import layout

    names = {getattr(layout, n) for n in RUN_NAMES} | {layout.mesh_file(f) for f in ("glb", "obj")}
    assert layout.REPORT_JSON == "report.json" and "mesh.glb" in names  # the names users' tools read
    where = []
    for root in CODE:
        for p in root.rglob("*.py"):
            if p == Path(layout.__file__):
                continue
            for c in _string_constants(ast.parse(p.read_text(encoding="utf-8"))):
                if c.value in names or c.value.lstrip("/") in names:  # a name the code uses, not prose naming it
                    where.append(f"{p.relative_to(PKG.parent)}:{c.lineno} {c.value!r}")
    assert not where, where


def test_only_run_folder_writes_a_run_folder():
    """A folder is written as a whole by io.output's output_folder, a file into one by add_output_file: outside
    run_folder/ only the synthetic scenes (scene folders, not runs) stage a folder, and nobody adds to one."""
    calls = []
    for root in CODE:
        for p in root.rglob("*.py"):
            rel = p.relative_to(PKG.parent)
            if rel.parts[:2] in (("o3d_seqcc", "run_folder"), ("o3d_seqcc", "synthetic")) or rel.parts[-2:] == ("io", "output.py"):
                continue
            for n in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
                if isinstance(n, ast.Call) and getattr(n.func, "id", getattr(n.func, "attr", "")) in (
                        "output_folder", "add_output_file"):
                    calls.append(f"{rel}:{n.lineno}")
    assert not calls, calls


if __name__ == "__main__":  # pragma: no cover - prints the graph for docs/ARCHITECTURE.md
    g = module_graph()
    for m in sorted(g):
        short = sorted(d.removeprefix("o3d_seqcc.") for d in g[m])
        print(f"{m.removeprefix('o3d_seqcc.') or 'o3d_seqcc'}: {', '.join(short) or '-'}")
    sys.exit(1 if find_cycle(g) else 0)
