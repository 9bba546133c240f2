"""One registry helper behind every method table (issue 23): one error style, literal tables, user entries."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

import o3d_seqcc as sc
from o3d_seqcc._shared.registry import Registry, UnknownNameError, UnknownOptionError
from o3d_seqcc.errors import InputError

ROOT = Path(__file__).resolve().parents[1]


def test_registry_get_names_register_and_check_options():
    reg = Registry("widget", {"b": lambda *, size=1: size, "a": lambda: 0})
    assert reg.names() == reg.list() == ["a", "b"] and "a" in reg and len(reg) == 2
    with pytest.raises(InputError, match=r"^unknown widget 'c'; valid: a, b$") as e:
        reg.get("c")
    assert isinstance(e.value, KeyError) and isinstance(e.value, UnknownNameError)
    with pytest.raises(KeyError):  # mapping code still sees a KeyError
        reg["c"]
    assert reg.get("c", None) is None
    reg.check_options("b", {"size": 2})
    with pytest.raises(UnknownOptionError, match=r"widget 'b' does not take option 'colour'; valid: size") as e:
        reg.check_options("b", {"colour": 1})
    assert isinstance(e.value, TypeError) and isinstance(e.value, InputError)

    @reg.register("c", flavour="x")
    def c(*, n=0, **rest):
        return n

    assert reg["c"] is c and reg.info("c") == {"flavour": "x"} and reg.names() == ["a", "b", "c"]
    reg.check_options("c", {"anything": 1})  # **rest takes any option
    reg.register("d", len, options=("k",))
    with pytest.raises(InputError, match="valid: k"):
        reg.check_options("d", {"j": 1})
    del reg["d"]
    assert "d" not in reg


def _tables():
    from meshlab_filters.filters import _registry
    from o3d_seqcc.correction import METHODS
    from o3d_seqcc.correction.cmf import CMF_METHODS
    from o3d_seqcc.io.load import SCENE_FORMATS
    from o3d_seqcc.texturing import SELECTION_METHODS

    return {"correction method": METHODS, "CMF method": CMF_METHODS, "selection method": SELECTION_METHODS,
            "scene format": SCENE_FORMATS, "MeshLab filter": _registry()}


def test_every_method_table_is_a_registry_naming_its_kind():
    for kind, table in _tables().items():
        assert isinstance(table, Registry) and table.kind == kind
        with pytest.raises(InputError) as e:
            table.get("bogus")
        assert str(e.value) == f"unknown {kind} 'bogus'; valid: {', '.join(sorted(table))}"


def test_every_dispatcher_rejects_an_unknown_name_with_the_sorted_valid_names(tmp_path):
    from meshlab_filters import get_filter
    from o3d_seqcc.correction import check_method, correct
    from o3d_seqcc.correction.cmf import fit_cmf
    from o3d_seqcc.io.load import detect_format
    from o3d_seqcc.texturing import select_views

    want = {
        "correction method": ("gain-compensation, histogram-matching, none, reinhard, root-polynomial, seqcc, "
                              "seqcc-global, seqcc-joint, vandermonde"),
        "CMF method": "csvr, isotonic, linear, polynomial",
        "selection method": "largest-area, mrf, random",
        "scene format": ("bundler, cam-folder, colmap, meshlab, meshroom, metashape, mve, nvm, openmvs, rgbd-folder, "
                         "scene.json"),
        "MeshLab filter": "seqcc_color_correct_rasters, seqcc_texture_from_rasters",
    }
    calls = {
        "correction method": [lambda: correct(images=[np.zeros((2, 2, 3))], mappings=object(), method="magic"),
                              lambda: check_method("magic")],
        "CMF method": [lambda: fit_cmf(np.linspace(0, 1, 50), np.linspace(0, 1, 50), method="magic")],
        "selection method": [lambda: select_views(object(), method="magic")],
        "scene format": [lambda: detect_format(tmp_path, format="magic")],
        "MeshLab filter": [lambda: get_filter("magic")],
    }
    for kind, fns in calls.items():
        for fn in fns:
            with pytest.raises(InputError, match=f"unknown {kind} 'magic'; valid: ") as e:
                fn()
            assert want[kind] in str(e.value), (kind, str(e.value))


def test_pipeline_and_correct_raise_the_same_error_for_an_unknown_method(tmp_path):
    from o3d_seqcc.correction import correct

    sc.make_synthetic_scene(tmp_path / "room", n_views=2, width=64, height=48, cell_size=0.3)
    errors = []
    for fn in (lambda: sc.pipeline.run(tmp_path / "room", method="magic"),
               lambda: correct(sc.load_scene(tmp_path / "room"), method="magic")):
        with pytest.raises(InputError) as e:
            fn()
        errors.append((type(e.value), str(e.value)))
    assert errors[0] == errors[1]


def test_a_registered_user_method_runs_through_correct_and_the_pipeline(tmp_path):
    from o3d_seqcc.correction import METHODS, FunctionTransform, available_methods, correct, register_method

    seen = {}

    @register_method("test-halve", needs_graph=False)
    def halve(ctx, *, factor: float = 0.5):
        seen["views"] = len(ctx.images)
        return [FunctionTransform(lambda c: c * factor) for _ in ctx.images]

    try:
        assert "test-halve" in available_methods() and sc.METHODS["test-halve"] is halve
        sc.make_synthetic_scene(tmp_path / "room", n_views=3, width=64, height=48, cell_size=0.3)
        scene = sc.load_scene(tmp_path / "room")
        res = correct(scene, method="test-halve", factor=0.25)
        assert seen["views"] == 3
        raw = scene.views[0].load_image()
        assert raw.dtype == np.uint8 and np.asarray(res.images[0]).dtype == np.uint8
        np.testing.assert_allclose(np.asarray(res.images[0], np.float64), raw * 0.25, atol=1)
        with pytest.raises(TypeError, match="'test-halve' does not take option 'bogus'; valid: factor"):
            correct(scene, method="test-halve", bogus=1)
    finally:
        del METHODS["test-halve"]
    assert "test-halve" not in available_methods()


def _module_level_calls(tree: ast.Module):
    """Calls a module makes when imported: top-level statements and decorators of top-level definitions
    (function and class bodies run later)."""
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            for d in node.decorator_list:
                yield from (n for n in ast.walk(d) if isinstance(n, ast.Call))
            continue
        yield from (n for n in ast.walk(node) if isinstance(n, ast.Call))


def _callee(call: ast.Call) -> str:
    f = call.func
    return f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""


def test_no_table_is_filled_by_an_import_side_effect():
    """No module of the package (nor meshlab_filters) calls a register function when imported: every built-in
    entry is written out in its table's literal, and nothing imports a module "for its registrations"."""
    offenders = []
    for path in [*(ROOT / "o3d_seqcc").rglob("*.py"), *(ROOT / "meshlab_filters").glob("*.py")]:
        text = path.read_text(encoding="utf-8")
        tree = ast.parse(text)
        for call in _module_level_calls(tree):
            if _callee(call).startswith("register") or (_callee(call) == "update" and "METHODS" in ast.unparse(call)):
                offenders.append(f"{path.relative_to(ROOT)}:{call.lineno}: {ast.unparse(call)[:60]}")
        if "register their methods" in text or "noqa: F401  (register" in text:
            offenders.append(f"{path.relative_to(ROOT)}: imports modules for their registrations")
    assert not offenders, offenders


def test_the_correction_table_is_a_literal_of_every_method():
    """``METHODS`` is the dict literal of ``correction/methods/__init__.py``, name by name."""
    from o3d_seqcc.correction import METHODS

    tree = ast.parse((ROOT / "o3d_seqcc" / "correction" / "methods" / "__init__.py").read_text())
    literal = next(n for n in ast.walk(tree) if isinstance(n, ast.Call) and _callee(n) == "Registry")
    table = literal.args[1]
    assert isinstance(table, ast.Dict)
    assert [k.value for k in table.keys] and sorted(k.value for k in table.keys) == METHODS.names()
    assert METHODS.info("none") == {"needs_graph": False} and METHODS.info("seqcc") == {}
