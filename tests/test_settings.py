"""The settings objects are where defaults live (issue 23): one home per option.

For every field of VisibilitySettings, CorrectionSettings, TextureSettings and RunSettings, the
command line's default, the effective default of every library entry point (called without the
option), the Open3D front door's, the pymeshlab filters' and the MeshLab plugin's table all equal
the dataclass default; the lists are built from the dataclasses. An AST scan checks that no
signature anywhere writes a field's default again as a literal. Plus the validation and the
unknown names.
"""

from __future__ import annotations

import argparse
import ast
import inspect
import warnings
from pathlib import Path

import numpy as np
import pytest

import o3d_seqcc as sc
from o3d_seqcc import open3d_api, pipeline
from o3d_seqcc._shared.options import UnknownSettingError
from o3d_seqcc.cli import build_parser
from o3d_seqcc.evaluation.fit import evaluate_scene
from o3d_seqcc.settings import STAGES, CorrectionSettings, RunSettings, TextureSettings, VisibilitySettings

ROOT = Path(__file__).resolve().parents[1]
OWN = [n for n in RunSettings.field_names() if n not in STAGES]  # the run's own options


def _all_defaults() -> dict[str, dict[str, object]]:
    """stage (or "run") -> field -> default, from the dataclasses."""
    out = {st: kind.defaults() for st, kind in STAGES.items()}
    out["run"] = {n: getattr(RunSettings(), n) for n in OWN}
    return out


DEFAULTS = _all_defaults()
FLAT = {n: d for st in DEFAULTS.values() for n, d in st.items()}  # seed is 0 in both of its stages
assert DEFAULTS["correction"]["seed"] == DEFAULTS["texture"]["seed"]

#: flags whose destination is named like a settings field but is another option (with its own default)
OTHER_OPTIONS = {
    ("demo", "seed"): "the synthetic scene's seed (o3d-seqcc synthetic --seed)",
    ("evaluate", "seed"): "the seed of the --holdout face split",
    ("evaluate", "mappings"): "evaluate scores Table 2 at the face vertices by default (the paper's)",
    ("evaluate", "method"): "without --method the images are scored as they are (no method is fitted)",
}


def _subparsers() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))  # noqa: SLF001
    return dict(sub.choices)


# ---- the command line ---------------------------------------------------------------------------------------------


def test_every_flag_of_a_settings_field_defaults_to_the_field():
    checked: dict[str, set[str]] = {}
    for command, p in _subparsers().items():
        for a in p._actions:  # noqa: SLF001
            if a.dest in FLAT and (command, a.dest) not in OTHER_OPTIONS:
                assert a.default == FLAT[a.dest], f"o3d-seqcc {command} {'/'.join(a.option_strings)}"
                checked.setdefault(command, set()).add(a.dest)
    # the commands that run stages expose their stages' options (not a hand list: the dataclasses')
    assert {"reference", "method", "t_npm", "mappings", "split_faces", "seams", "compare_original"} <= checked["run"]
    assert set(DEFAULTS["texture"]) - {"fill_background"} <= checked["run"] & checked["texture"]
    assert {"reference", "method", "t_npm", "mappings", "seed", "graph_weight", "metrics", "split_faces"} \
        <= checked["correct"]
    assert {"mappings", "max_angle", "depth_tol", "depth_atol", "occlusion_tol", "oblique_reference", "two_sided",
            "depth_edge_margin"} <= checked["mappings"]
    assert {"t_npm", "atlas_size", "padding"} <= checked["demo"] and {"reference", "t_npm"} <= checked["evaluate"]


def test_default_command_lines_build_the_default_settings():
    from o3d_seqcc.cli.texture_flags import run_options_from_args

    subs = _subparsers()
    run = subs["run"].parse_args(["s.json", "--out", "o"])
    assert run_options_from_args(run) == RunSettings()
    correct = subs["correct"].parse_args(["s.json", "--out", "o"])
    assert run_options_from_args(correct, texture=False) == RunSettings()
    texture = subs["texture"].parse_args(["s.json", "--out", "o"])
    assert run_options_from_args(texture) == RunSettings()
    # and a changed flag reaches its field (run --seed seeds both stages; correct --seed the correction)
    rs = run_options_from_args(subs["run"].parse_args(["s", "--out", "o", "--seed", "3", "--no-split-faces",
                                                       "--mappings", "vertices", "--t-npm", "50"]))
    assert (rs.texture.seed, rs.correction.seed, rs.visibility.split_faces, rs.correction.mappings,
            rs.correction.t_npm) == (3, 3, False, "vertices", 50)
    rs = run_options_from_args(subs["correct"].parse_args(["s", "--out", "o", "--seed", "3", "--no-metrics"]),
                               texture=False)
    assert (rs.correction.seed, rs.texture.seed, rs.metrics) == (3, 0, False)


def test_help_texts_show_the_settings_defaults():
    help_text = " ".join(_subparsers()["run"].format_help().split())
    assert f"(default {CorrectionSettings().method};" in help_text
    assert f"(default {sc.scene.View.depth_scale:g}: millimetres)" in help_text
    assert "(default glb,obj)" in help_text


# ---- the library's entry points -----------------------------------------------------------------------------------


ENTRY_POINTS = [sc.compute_visibility, sc.compute_mappings, sc.correct, pipeline.run, pipeline.texture,
                pipeline.correct_scene, open3d_api.correct_images, open3d_api.texture_mesh, sc.run_demo,
                sc.evaluate_method, evaluate_scene, sc.evaluate_semireal]
#: (function, keyword): the same name for another option, with its own default
OTHER_KEYWORDS = {("evaluate_method", "seed"): "the seed of the holdout face split",
                  ("evaluate_scene", "seed"): "the seed of the holdout face split",
                  ("evaluate_scene", "mappings"): "Table 2 at the face vertices (the paper's) by default",
                  ("evaluate_scene", "method"): "None: the images are scored as they are",
                  ("evaluate_semireal", "reference"): "the unchanged view of the semi-real ground truth (view 0)"}


@pytest.mark.parametrize("fn", ENTRY_POINTS, ids=lambda f: f.__name__)
def test_entry_point_signatures_write_no_default_again(fn):
    for name, p in inspect.signature(fn).parameters.items():
        if name in FLAT and (fn.__name__, name) not in OTHER_KEYWORDS:
            assert p.default in (None, inspect.Parameter.empty), f"{fn.__name__}({name}={p.default!r})"
    # every entry point takes settings=, or passes its options to one that does
    assert "settings" in inspect.signature(fn).parameters or fn.__name__.startswith(("evaluate", "compute_mappings"))


class _Stop(Exception):
    pass


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    return sc.make_synthetic_scene(tmp_path_factory.mktemp("settings") / "S", n_views=4, width=96, height=72, seed=2)


def test_compute_visibility_and_mappings_run_with_the_defaults(tiny):
    vis = sc.compute_visibility(tiny.scene)
    assert vis.settings == VisibilitySettings()
    assert vis.options == VisibilitySettings().filter_options()
    assert vis.stats["split"]["enabled"] is VisibilitySettings().split_faces
    maps = sc.compute_mappings(tiny.scene, visibility=vis)
    assert maps.mode == CorrectionSettings().mappings
    assert sc.compute_mappings(tiny.scene).visibility.settings == VisibilitySettings()
    changed = sc.compute_visibility(tiny.scene, max_angle=60, settings=VisibilitySettings(depth_tol=0.1))
    assert (changed.settings.max_angle, changed.settings.depth_tol) == (60, 0.1)


def test_correct_runs_with_the_defaults(tiny, monkeypatch):
    maps = sc.compute_mappings(tiny.scene)
    res = sc.correct(tiny.scene, mappings=maps)
    d = CorrectionSettings()
    assert res.method == d.method
    assert res.settings == {"t_npm": d.t_npm, "seed": d.seed, "interpolation": d.interpolation,
                            "graph_weight": d.graph_weight, "options": d.method_options}
    seen = {}

    def fake(scene, **kw):
        seen.update(kw)
        raise _Stop

    monkeypatch.setattr(sc.mappings.compute, "compute_mappings", fake)  # correct() without mappings computes them
    with pytest.raises(_Stop):
        sc.correct(tiny.scene)
    assert seen == {"mappings": d.mappings}


def _record_stages(monkeypatch, seen: dict) -> None:
    """pipeline's stages replaced by recorders (no work): what settings each stage is called with."""
    from types import SimpleNamespace

    def vis(scene, settings=None, **kw):
        seen["visibility"] = settings
        return SimpleNamespace(mesh=None)

    def maps(scene, mappings=None, settings=None, **kw):
        seen["mappings"], seen["mappings_visibility"] = mappings, settings
        return SimpleNamespace(counts={})

    def corr(scene, settings=None, **kw):
        seen["correction"] = settings
        return SimpleNamespace(images=[], timings={}, method="", reference=0, t_npm=1, graph_edges=[], paths={},
                               unreachable=[], transforms=[], settings={}, edge_residuals={})

    def tex(scene, images, v, s, timings, *, want_seams, **kw):
        seen["texture"], seen["seams"] = s, want_seams
        return None, {}, None, None

    monkeypatch.setattr(pipeline, "compute_visibility", vis)
    monkeypatch.setattr(pipeline, "compute_mappings", maps)
    monkeypatch.setattr(pipeline, "correct", corr)
    monkeypatch.setattr(pipeline, "_texture_stage", tex)


def test_pipeline_runs_with_the_defaults(tiny, monkeypatch):
    seen: dict = {}
    _record_stages(monkeypatch, seen)
    res = pipeline.run(tiny.scene)
    d = RunSettings()
    assert res.run_settings == d
    assert (seen["visibility"], seen["mappings"], seen["correction"], seen["texture"], seen["seams"]) \
        == (d.visibility, d.correction.mappings, d.correction, d.texture, d.seams)
    seen.clear()
    res = pipeline.texture(tiny.scene)
    assert res.run_settings == d and (seen["visibility"], seen["texture"], seen["seams"]) == (
        d.visibility, d.texture, d.seams)
    seen.clear()
    monkeypatch.setattr(pipeline, "before_after", lambda *a, **k: {})
    monkeypatch.setattr(tiny.scene.views[0].__class__, "load_image", lambda self: np.zeros((2, 2, 3), np.uint8))
    job = pipeline.correct_scene(tiny.scene)
    assert (seen["mappings"], seen["mappings_visibility"], seen["correction"]) == (
        d.correction.mappings, d.visibility, d.correction)
    # report.json (one schema, issue 23): the correction's part records the mode; its settings are the
    # CorrectionResult's own record (the stub's is empty); metrics are on by default
    assert (job.report["correction"]["mappings"], job.report["metrics"] is not None) == (
        d.correction.mappings, d.metrics)
    # the old keywords still work, and reach their stage
    seen.clear()
    res = pipeline.run(tiny.scene, method="seqcc", t_npm=50, mappings="dense", split_faces=False, seed=2, atlas_size=512,
                       compare_original=False)
    rs = res.run_settings
    assert (rs.correction.method, rs.correction.t_npm, rs.correction.mappings, rs.visibility.split_faces,
            rs.correction.seed, rs.texture.seed, rs.texture.atlas_size) == ("seqcc", 50, "dense", False, 2, 2, 512)


def test_open3d_front_door_runs_with_the_defaults(tiny, monkeypatch):
    import open3d as o3d

    scene = tiny.scene
    mesh = o3d.io.read_triangle_mesh(str(scene.mesh))
    images = [v.load_image() for v in scene.views]
    cams = ([v.intrinsic for v in scene.views], [v.extrinsic for v in scene.views])
    seen = {}

    def record(name):
        def fn(scene, settings=None, **kw):
            seen[name] = settings.replace(**kw) if kw else settings
            raise _Stop
        return fn

    for name in ("run", "texture", "correct_scene"):
        monkeypatch.setattr(pipeline, name, record(name))
    with pytest.raises(_Stop):
        sc.texture_mesh(mesh, images, cams)
    assert seen["run"] == RunSettings()
    with pytest.raises(_Stop):
        sc.texture_mesh(mesh, images, cams, correct=False)
    assert seen["texture"] == RunSettings()
    with pytest.raises(_Stop):
        sc.correct_images(mesh, images, cams)
    # without return_report the front door skips the metrics (the report is not returned)
    assert seen["correct_scene"] == RunSettings(metrics=False)
    for fn in (sc.texture_mesh, sc.correct_images):
        assert inspect.signature(fn).parameters["depth_scale"].default == sc.scene.View.depth_scale
    assert inspect.signature(sc.load_scene).parameters["depth_scale"].default == sc.scene.View.depth_scale


# ---- the pymeshlab filters and the MeshLab plugin ------------------------------------------------------------------


def _filter_stage(filter_name: str, keyword: str) -> str | None:
    """Which settings object a filter parameter's keyword is a field of (None: not a setting)."""
    if keyword in DEFAULTS["run"]:
        return "run"
    if keyword == "seed":  # the correction's seed in the correct filter, the selection's in the texture filter
        return "correction" if filter_name == "seqcc_color_correct_rasters" else "texture"
    return next((st for st in STAGES if keyword in DEFAULTS[st]), None)


def test_pymeshlab_filters_and_the_meshlab_plugin_show_the_settings_defaults():
    from meshlab_filters import filters
    from meshlab_filters.native import _default_text, native_filters

    seen = set()
    for name in filters.filter_list():
        for p in filters.get_filter(name).parameters:
            st = _filter_stage(name, p.keyword)
            if st is not None:
                assert p.default == DEFAULTS[st][p.keyword], f"{name}: {p.name}"
                seen.add(p.keyword)
    # every texture field, the correction's reference / method / t_npm / mappings / graph_weight / seed, the run's own
    assert set(DEFAULTS["texture"]) | {"reference", "method", "t_npm", "mappings", "graph_weight", "seed", "seams",
                                       "metrics"} <= seen
    n = 0
    for nf in native_filters():
        for p in nf["parameters"]:
            st = _filter_stage(nf["python_name"], p["keyword"])
            if st is not None:
                assert p["default"] == _default_text(DEFAULTS[st][p["keyword"]]), f"{nf['title']}: {p['name']}"
                n += 1
    assert n >= 8


# ---- no second literal anywhere ------------------------------------------------------------------------------------

#: (module, function, parameter): a parameter named like a settings field that is another option
SCAN_EXCEPTIONS = {
    ("o3d_seqcc/imaging/arrays.py", "sample_colors", "interpolation"):
        "imaging is the shared layer below every stage (it cannot import a stage's settings); the correction passes "
        "CorrectionSettings.interpolation",
    ("o3d_seqcc/evaluation/metrics.py", "evaluate", "interpolation"):
        "Table 2's scoring samples bilinearly as the paper does, an option of the evaluation (cheap to import: no "
        "correction package)",
}


def _literal(node):
    try:
        return True, ast.literal_eval(node)
    except (ValueError, TypeError, SyntaxError):
        return False, None


def test_no_signature_writes_a_settings_default_again():
    """An AST scan of the package and the MeshLab layer: a parameter named like a settings field whose default is
    that field's default written as a literal is a second home (``t_npm="auto"``, ``method="seqcc-global"``)."""
    settings_modules = {"o3d_seqcc/settings.py", "o3d_seqcc/visibility/settings.py",
                        "o3d_seqcc/correction/settings.py", "o3d_seqcc/texturing/settings.py"}
    # generic names (seed=0, padding=4, ...) are other options in other functions: the distinctive ones are scanned
    generic = {"seed", "filters", "leveling", "smoothness", "fill_background", "metrics", "seams"}
    bad = []
    for path in [*(ROOT / "o3d_seqcc").rglob("*.py"), *(ROOT / "meshlab_filters").rglob("*.py")]:
        rel = path.relative_to(ROOT).as_posix()
        if rel in settings_modules:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            a = node.args
            pos = a.posonlyargs + a.args
            pairs = list(zip(pos[len(pos) - len(a.defaults):], a.defaults)) + [
                (k, d) for k, d in zip(a.kwonlyargs, a.kw_defaults) if d is not None]
            for arg, default in pairs:
                name = arg.arg
                if name not in FLAT or (rel, node.name, name) in SCAN_EXCEPTIONS:
                    continue
                ok, value = _literal(default)
                if not ok:
                    continue
                if value is not None and (name == "t_npm" or (name not in generic and value == FLAT[name])):
                    bad.append(f"{rel}:{node.lineno} {node.name}({name}={value!r})")
    assert not bad, bad


def test_the_scan_finds_a_planted_default(tmp_path):
    tree = ast.parse('def f(*, t_npm="auto", method="seqcc-global", max_angle=75.0):\n    pass\n')
    fn = tree.body[0]
    found = [k.arg for k, d in zip(fn.args.kwonlyargs, fn.args.kw_defaults) if _literal(d)[1] == FLAT[k.arg]]
    assert found == ["t_npm", "method", "max_angle"]


# ---- validation and unknown names ---------------------------------------------------------------------------------


@pytest.mark.parametrize("cls, field, value, words", [
    (VisibilitySettings, "max_angle", 0, ["max_angle", "(0, 180]"]),
    (VisibilitySettings, "oblique_reference", "normal", ["oblique_reference", "'ray', 'axis'"]),
    (VisibilitySettings, "filters", ("oblique", "bogus"), ["bogus", "occlusion, depth, oblique"]),
    (VisibilitySettings, "occlusion_tol", 1.5, ["occlusion_tol", "[0, 1)"]),
    (VisibilitySettings, "fill_radius", "six", ["fill_radius", "an integer"]),
    (CorrectionSettings, "method", "seqcc-best", ["seqcc-best", "seqcc-global", "vandermonde"]),
    (CorrectionSettings, "t_npm", 0, ["t_npm", "'auto' or a positive integer"]),
    (CorrectionSettings, "mappings", "pixels", ["mappings", "'surface', 'vertices', 'dense'"]),
    (CorrectionSettings, "graph_weight", "heavy", ["graph_weight", "'paper', 'log'"]),
    (CorrectionSettings, "interpolation", "cubic", ["interpolation", "'bilinear', 'nearest'"]),
    (CorrectionSettings, "reference", 1.5, ["reference", "'auto'"]),
    (TextureSettings, "fallback", "blue", ["fallback", "'smooth', 'flat'"]),
    (TextureSettings, "padding", 100, ["padding", "0..64"]),
    (RunSettings, "seams", "yes", ["seams", "True or False"]),
    (RunSettings, "selection", "best", ["selection", "largest-area", "mrf"]),
])
def test_bad_values_name_the_field_and_the_valid_values(cls, field, value, words):
    with pytest.raises(sc.InputError) as e:
        cls.from_options(**{field: value})
    for w in words:
        assert w in str(e.value), str(e.value)


def test_unknown_names_list_the_valid_ones():
    for cls in (VisibilitySettings, CorrectionSettings, TextureSettings, RunSettings):
        with pytest.raises(UnknownSettingError) as e:
            cls.from_options(bogus=1)
        assert isinstance(e.value, TypeError) and isinstance(e.value, sc.InputError)
        assert "bogus" in str(e.value) and all(n in str(e.value) for n in cls.field_names())
        with pytest.raises(UnknownSettingError):
            cls().replace(bogus=1)
    with pytest.raises(TypeError, match=r"did you mean 'max_angle'"):
        RunSettings.from_options(max_angel=60)
    with pytest.raises(TypeError, match=r"method"):  # texture() does not correct
        pipeline.texture("scene.json", method="seqcc")
    with pytest.raises(TypeError, match=r"atlas_size"):  # correct_scene() does not texture
        pipeline.correct_scene("scene.json", atlas_size=512)
    with pytest.raises(TypeError, match=r"bogus.*valid: bits"):  # a method's options are the method's
        CorrectionSettings(method="seqcc", method_options={"bogus": 1})
    with pytest.raises(sc.InputError, match="settings must be a VisibilitySettings"):
        sc.compute_visibility(None, settings=TextureSettings())


def test_replace_routes_flat_names_and_keeps_the_rest():
    rs = RunSettings.from_options(method="seqcc", max_angle=60, atlas_size=1024, seed=5, seams=False)
    assert (rs.correction.method, rs.visibility.max_angle, rs.texture.atlas_size, rs.correction.seed, rs.texture.seed,
            rs.seams) == ("seqcc", 60, 1024, 5, 5, False)
    assert rs.replace(t_npm=9).correction == rs.correction.replace(t_npm=9)  # one field changed, the rest kept
    whole = rs.replace(visibility=VisibilitySettings(two_sided=True), depth_tol=0.2)
    assert whole.visibility == VisibilitySettings(two_sided=True, depth_tol=0.2)
    assert RunSettings().replace() == RunSettings() and VisibilitySettings().replace() == VisibilitySettings()
    # a stage's settings given to a run replace that stage; a TextureSettings' seed seeds the correction too
    r = RunSettings.resolve(TextureSettings(seed=4, atlas_size=256))
    assert (r.texture.atlas_size, r.correction.seed, r.visibility) == (256, 4, VisibilitySettings())
    assert RunSettings.resolve(CorrectionSettings(method="none")).correction.method == "none"
    assert RunSettings.resolve(None, {"method": None}) == RunSettings()  # None: the settings' value
    with pytest.raises(AttributeError):
        VisibilitySettings().max_angle = 10  # frozen
    assert TextureSettings().updated(padding=2) == TextureSettings(padding=2)  # its earlier name still works
    assert VisibilitySettings.defaults()["filters"] == ("occlusion", "depth", "oblique")
    assert RunSettings().to_dict()["correction"]["t_npm"] == "auto"


def test_one_name_for_the_mapping_mode(tiny):
    """``mappings`` everywhere: pipeline.run, correct (a mode or precomputed Mappings), compute_mappings, --mappings."""
    vis = sc.compute_visibility(tiny.scene)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert sc.compute_mappings(tiny.scene, visibility=vis, mappings="vertices").mode == "vertices"
    with pytest.warns(DeprecationWarning, match="mappings="):
        assert sc.compute_mappings(tiny.scene, visibility=vis, mode="dense").mode == "dense"
    with pytest.raises(sc.InputError, match="disagree"), pytest.warns(DeprecationWarning):
        sc.compute_mappings(tiny.scene, visibility=vis, mode="dense", mappings="vertices")
    seen = {}

    def fake(scene, **kw):
        seen.update(kw)
        raise _Stop

    import o3d_seqcc.mappings.compute as mc

    orig = mc.compute_mappings
    mc.compute_mappings = fake
    try:
        with pytest.raises(_Stop):
            sc.correct(tiny.scene, mappings="dense")
    finally:
        mc.compute_mappings = orig
    assert seen == {"mappings": "dense"}
    with pytest.raises(TypeError, match="mappings_mode"):  # the old name of correct() is gone (never documented)
        sc.correct(tiny.scene, mappings_mode="dense")


def test_every_field_is_documented_with_its_default():
    """numpydoc ``Attributes``: one entry per field, saying its default (what the filters' and plugin's help shows)."""
    from meshlab_filters.filters import _doc_entries

    for cls in (VisibilitySettings, CorrectionSettings, TextureSettings, RunSettings):
        doc = inspect.getdoc(cls)
        assert set(_doc_entries(cls, "Attributes")) == set(cls.field_names()), cls.__name__
        for name in cls.field_names():
            head = next(line for line in doc.splitlines() if line.startswith(name + " :"))
            assert "default" in head, head
