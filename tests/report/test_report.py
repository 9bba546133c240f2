"""The HTML report: self-contained, the paper's figures for the run, numbers equal to report.json's."""

from __future__ import annotations

import base64
import json
import re
import shutil
import struct
import subprocess
import tempfile

import cv2
import numpy as np
import pytest

import o3d_seqcc as sc
from o3d_seqcc.cli import main
from o3d_seqcc.io.output import MANIFEST
from o3d_seqcc.correction.luts import compose_luts
from o3d_seqcc.run_folder.read import regenerate_report
from o3d_seqcc.report.page import MAX_DETAIL_EDGES
from o3d_seqcc.report.viewer import viewer_bundle

FAST = ["--t-npm", "50", "--atlas-size", "1024", "--format", "glb", "--fallback", "flat"]
IMG = re.compile(r'<img(?: class="[^"]*")? src="data:image/(png|jpeg);base64,([A-Za-z0-9+/=]+)" alt="[^"]*">')


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    return sc.make_synthetic_scene(tmp_path_factory.mktemp("rep") / "scene", n_views=5, width=160, height=120, seed=3)


@pytest.fixture(scope="module")
def run_dir(scene, tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "out"
    assert main(["-q", "run", str(scene.root / "scene.json"), "--out", str(out), *FAST]) == 0
    return out


def _sections(page: str) -> dict[str, str]:
    return dict(re.findall(r'<section id="([a-z0-9]+)">(.*?)</section>', page, flags=re.S))


def _images(fragment: str) -> list[tuple[str, bytes]]:
    return [(kind, base64.b64decode(data)) for kind, data in IMG.findall(fragment)]


def _scripts(page: str) -> tuple[str, list[tuple[str, str]]]:
    """The page without its scripts, and the scripts as (opening tag, content)."""
    found = re.findall(r"(<script[^>]*>)(.*?)</script>", page, flags=re.S)
    return re.sub(r"<script[^>]*>.*?</script>", "", page, flags=re.S), found


def test_the_report_is_one_self_contained_file(run_dir):
    page = (run_dir / "report.html").read_text(encoding="utf-8")
    assert page.startswith("<!DOCTYPE html>") and page.rstrip().endswith("</html>")
    # every image embedded, and decodable as what it says it is
    imgs = _images(page)
    assert len(imgs) == page.count("<img") > 20
    for kind, data in imgs:
        assert data[:8] == b"\x89PNG\r\n\x1a\n" if kind == "png" else data[:3] == b"\xff\xd8\xff", kind
    # two scripts, both inline: the viewer's data (JSON) and the viewer, exactly the bundle the package ships
    rest, scripts = _scripts(page)
    assert [tag for tag, _ in scripts] == ['<script type="application/json" id="o3d-viewer-data">', "<script>"]
    assert scripts[1][1] == viewer_bundle()
    data = json.loads(scripts[0][1])
    glb = base64.b64decode(data["glb"])
    assert glb[:4] == b"glTF" and struct.unpack("<I", glb[8:12])[0] == len(glb)
    for m in data["modes"][1:]:
        assert m["texture"].startswith("data:image/jpeg;base64,")
    # nothing fetched from anywhere: no URL, no stylesheet link, no CSS url(), outside the scripts and in the data
    for bad in ("http://", "https://", "<link", "url(", "@import", "src=\"/", "src='", "file:"):
        assert bad not in rest and bad not in scripts[0][1], bad
    assert re.findall(r'src="(?!data:)', rest) == [] and re.findall(r'href="(?!#)', rest) == []
    # the bundle names no address it could load (three.js's XHTML namespace string is not a request)
    assert set(re.findall(r"https?://[^\s\"'`)]+", scripts[1][1])) <= {"http://www.w3.org/1999/xhtml"}


def test_the_report_shows_this_run(run_dir, scene):
    rep = json.loads((run_dir / "report.json").read_text())
    page = (run_dir / "report.html").read_text(encoding="utf-8")
    sec = _sections(page)
    assert list(sec) == ["model", "correction", "views", "table2", "graph", "jih", "steps", "selection", "renders",
                         "seams", "timings", "settings"]
    names, ref = scene.scene.names, rep["correction"]["reference"]
    paths = rep["correction"]["paths"]
    n_views = len(names)
    # Figures 4-5: the caption names the reference; one table row per path edge
    edges = {(p[i], p[i + 1]) for p in paths.values() for i in range(len(p) - 1)}
    assert f"the reference <b>{ref}</b>" in sec["graph"] and len(_images(sec["graph"])) == 0
    svg = re.findall(r"<svg .*?</svg>", sec["graph"], flags=re.S)  # drawn as SVG: one node per view, one arrow per edge
    assert len(svg) == 1 and svg[0].count("<circle ") == n_views
    assert svg[0].split('<g class="arrows" stroke="#000">')[1].split("</g>")[0].count("<line ") == len(edges)
    assert sec["graph"].count("<tr><td>") == len(edges)
    # every graph edge's residual before and after the correction (seqcc-global, the default, measures them)
    resid = rep["correction"]["edge_residuals"]
    assert len(resid) == rep["correction"]["n_graph_edges"] == sec["graph"].count('<tr class="residual">')
    assert all(r["after"] < r["before"] for r in resid), resid  # the demo room's photos differ by camera changes
    means: dict = {}
    for r in resid:
        for k in ("a_name", "b_name"):
            if r[k] != ref:
                means.setdefault(r[k], []).append(r["after"])
    means = {k: float(np.mean(v)) for k, v in means.items()}
    bound = max(2.0, 1.5 * float(np.median(list(means.values()))))
    assert rep["correction"]["out_of_line"] == sorted((k for k, m in means.items() if m > bound), key=names.index)
    for name in rep["correction"]["out_of_line"]:
        assert name in sec["graph"].split("could not bring in line")[1].split("</b>")[0]
    # Figures 6-7: three channels of the path's edges (at most MAX_DETAIL_EDGES), one thumbnail per path edge
    detail = min(max(len(p) for p in paths.values()) - 1, MAX_DETAIL_EDGES)
    assert len(_images(sec["jih"])) == 3 * detail + len(edges)
    # Figure 8: the longest path, its views above, one step (image + CMF) per edge below
    hops = max(len(p) for p in paths.values()) - 1
    # (+ its corrected image after the joint refinement: the default method refines the sequential estimate)
    refined = rep["correction"]["method"] != "seqcc"
    assert len(_images(sec["steps"])) == (hops + 1) + 2 * hops + refined and f"{hops} step(s)" in sec["steps"]
    assert ("after the joint refinement" in sec["steps"]) == refined
    # Figure 10: every view before and after, the reference marked
    assert len(_images(sec["views"])) == 2 * n_views
    assert sec["views"].count('<figure class="ref">') == 1
    assert re.search(rf'<figure class="ref">.*?#{names.index(ref)} {ref} <span class="badge">reference', sec["views"])
    # Table 2: the numbers of report.json
    m = rep["metrics"]
    cells = dict(re.findall(r'<td data-key="([a-z0-9_.]+)">([^<]*)</td>', sec["table2"]))
    assert len(cells) == 16
    for when in ("before", "after"):
        for metric in ("psnr", "ciede2000"):
            for stat in ("mean", "weighted_mean", "std"):
                assert cells[f"{when}.{metric}.{stat}"] == f"{m[when][metric][stat]:.2f}"
        for stat in ("mean", "min"):
            assert cells[f"contrast.{when}.{stat}"] == f"{m['contrast'][when][stat]:.3f}"
    assert m["after"]["ciede2000"]["mean"] < m["before"]["ciede2000"]["mean"]
    assert "max_per_pair" not in m["before"]  # a small scene: every mapping scored, as correct does
    # Figure 9: the legend counts the faces of selection.npy
    sel = np.load(run_dir / "selection.npy")
    counts = np.bincount(sel[sel >= 0], minlength=n_views)
    legend = dict(re.findall(r"</span>#\d+ (\w+): (\d+) faces</li>", sec["selection"]))
    assert legend == {names[v]: str(counts[v]) for v in range(n_views) if counts[v]}
    assert f"seen by no view: {int((sel < 0).sum())} faces" in sec["selection"]
    # Figures 12-13: two cameras, photo / corrected photo / render each
    assert len(_images(sec["renders"])) == 6
    assert f"{rep['seams']['mean']:.3f}" in sec["seams"]
    # the atlas facts of report.json in the summary cards
    a = rep["atlas"]
    assert f"<span>texture atlas</span><b>{a['page_width']} × {a['page_height']}</b>" in page
    mib = a["texture_memory"]["gpu_bytes"] / 2**20
    assert f"<span>GPU texture memory (RGBA8, mipmaps)</span><b>{mib:.1f} MiB</b>" in page
    assert f"<span>atlas covered by triangles</span><b>{100 * a['coverage']:.0f} %</b>" in page


@pytest.mark.parametrize("method", ["seqcc", "seqcc-global"])
def test_the_edge_luts_compose_to_the_views_transforms(scene, method):
    res = sc.correct(scene.scene, t_npm=50, method=method)
    assert res.settings == {"t_npm": 50, "seed": 0, "interpolation": "bilinear", "graph_weight": "paper", "options": {}}
    assert set(res.edge_luts) == {(p[i], p[i + 1]) for p in res.paths.values() for i in range(len(p) - 1)}
    for v, p in res.paths.items():
        if len(p) > 1:
            luts = [res.edge_luts[(p[i], p[i + 1])] for i in range(len(p) - 1)]
            composed = np.stack([compose_luts([lut[c] for lut in luts], n_out=256) for c in range(3)])
            if method == "seqcc":  # the paper's method: the composition is the view's correction
                np.testing.assert_allclose(composed, res.transforms[v].lut, atol=1e-12)
            else:  # seqcc-global starts from it (same path, same steps) and refines: close, not equal
                assert np.abs(composed - res.transforms[v].lut).mean() < 0.05


def test_report_command_writes_the_same_report_again(run_dir, tmp_path, capsys):
    copy = tmp_path / "copy"
    shutil.copytree(run_dir, copy)
    before = (copy / "report.html").read_text(encoding="utf-8")
    (copy / "report.html").unlink()
    assert main(["report", str(copy)]) == 0
    assert str(copy / "report.html") in capsys.readouterr().out
    again = (copy / "report.html").read_text(encoding="utf-8")
    assert "report.html" in json.loads((copy / MANIFEST).read_text())["files"]  # still o3d-seqcc's own folder
    # the same figures and numbers (the renders of the mesh reloaded from mesh.glb may differ by a bit)
    a, b = _sections(before), _sections(again)
    assert list(a) == list(b)
    for sid in a:
        assert len(_images(a[sid])) == len(_images(b[sid])), sid
    for sid in ("table2", "seams", "settings"):
        assert a[sid] == b[sid], sid
    assert a["graph"] == b["graph"]  # the correction recomputed is the run's
    assert _images(a["jih"]) == _images(b["jih"])
    # mesh.glb is Y-up (report.json's export.orientation): reloaded, it is rotated back into the cameras' frame
    assert json.loads((copy / "report.json").read_text())["export"]["orientation"]["up_axis"] == "y"
    for (_, x), (_, y) in list(zip(_images(a["renders"]), _images(b["renders"])))[2::3]:
        x, y = (cv2.imdecode(np.frombuffer(im, np.uint8), cv2.IMREAD_COLOR).astype(float) for im in (x, y))
        white = (y > 250).all(axis=2).mean()
        assert np.abs(x - y).mean() < 3 and abs((x > 250).all(axis=2).mean() - white) < 0.01, white


def test_report_refuses_a_folder_that_is_no_output(tmp_path, capsys):
    with pytest.raises(sc.InputError, match=rf"{re.escape(str(tmp_path))} is not an o3d-seqcc output folder "
                                            r"\(no report.json\); give the --out folder"):
        regenerate_report(tmp_path)
    assert main(["report", str(tmp_path / "missing")]) == 2
    assert "is not a folder" in capsys.readouterr().err


def test_correct_writes_a_report_with_the_full_table(scene, tmp_path):
    job = sc.pipeline.correct_scene(scene.scene, t_npm=50)
    job.save(tmp_path / "c")
    page = (tmp_path / "c" / "report.html").read_text(encoding="utf-8")
    sec = _sections(page)
    assert list(sec) == ["views", "table2", "graph", "jih", "steps", "timings", "settings"]
    rep = json.loads((tmp_path / "c" / "report.json").read_text())
    assert "max_per_pair" not in rep["metrics"]["before"]  # correct scores every mapping
    cells = dict(re.findall(r'<td data-key="([a-z0-9_.]+)">([^<]*)</td>', sec["table2"]))
    assert cells["after.ciede2000.mean"] == f"{rep['metrics']['after']['ciede2000']['mean']:.2f}"
    assert cells["contrast.after.mean"] == f"{rep['metrics']['contrast']['after']['mean']:.3f}"


@pytest.mark.skipif(shutil.which("chromium") is None, reason="Debian's chromium is not installed (./dev.sh setup)")
def test_the_report_renders_in_headless_chromium(run_dir, tmp_path):
    from scipy import ndimage

    from o3d_seqcc.io.images import read_image

    shot = tmp_path / "shot.png"
    with tempfile.TemporaryDirectory() as profile:
        cmd = ["chromium", "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
               "--disable-background-networking", "--disable-component-update", "--disable-sync",
               f"--user-data-dir={profile}", "--hide-scrollbars", f"--screenshot={shot}", "--window-size=1280,2400",
               (run_dir / "report.html").resolve().as_uri()]
        subprocess.run(cmd, check=True, capture_output=True, timeout=120)
    img = read_image(shot).astype(np.int16)
    assert img.shape == (2400, 1280, 3)
    # not blank: the page background with several pictures on it (large regions far from the background)
    background = np.median(img.reshape(-1, 3), axis=0)
    ink = np.abs(img - background).max(axis=2) > 40
    assert 0.05 < ink.mean() < 0.9
    labels, n = ndimage.label(ndimage.binary_closing(ink, iterations=2))
    big = np.sort(np.bincount(labels.ravel())[1:])[::-1]
    assert (big > 4000).sum() >= 6, big[:10]


def test_table2_is_what_correct_gives_with_the_command_the_report_names(run_dir, tmp_path):
    import html
    import shlex

    sec = _sections((run_dir / "report.html").read_text(encoding="utf-8"))
    cmd = html.unescape(re.search(r"<code>(o3d-seqcc correct [^<]*)</code>", sec["table2"]).group(1))
    argv = shlex.split(cmd)[1:]
    argv[argv.index("OUT")] = str(tmp_path / "c")
    assert main(["-q", *argv]) == 0
    ran, full = (json.loads((d / "report.json").read_text()) for d in (run_dir, tmp_path / "c"))
    assert full["correction"]["reference"] == ran["correction"]["reference"]
    assert full["correction"]["paths"] == ran["correction"]["paths"]
    assert list(full) == list(ran) and full["schema"] == ran["schema"]  # one report.json schema for both commands
    # the same correction scored on the same mappings (a small scene: all of them): the same table
    assert "gives this very table" in sec["table2"]
    page_c = _sections((tmp_path / "c" / "report.html").read_text(encoding="utf-8"))["table2"]
    cells = re.compile(r'<td data-key="([a-z0-9_.]+)">([^<]*)</td>')
    assert dict(cells.findall(sec["table2"])) == dict(cells.findall(page_c))
    for when in ("before", "after"):
        for metric in ("psnr", "ciede2000"):
            assert full["metrics"][when][metric]["mean"] == pytest.approx(ran["metrics"][when][metric]["mean"], abs=1e-9)
    assert full["metrics"]["before"]["n_mappings"] == ran["metrics"]["before"]["n_mappings"]


def test_the_selection_legend_colours_are_told_apart_and_the_seam_steps_are_report_json_s(run_dir):
    from o3d_seqcc.imaging.arrays import delta_e_2000

    page = (run_dir / "report.html").read_text(encoding="utf-8")
    sec = _sections(page)
    rgb = np.array([list(map(int, c)) for c in re.findall(r"background:rgb\((\d+),(\d+),(\d+)\)", sec["selection"])])
    views = rgb[:-1]  # the last swatch: faces seen by no view
    assert len(views) >= 3
    d = delta_e_2000(views[:, None] / 255.0, views[None] / 255.0)
    np.fill_diagonal(d, np.inf)
    assert d.min() > 15, d.min()
    steps = json.loads((run_dir / "report.json").read_text())["selection_seams"]
    a, b = steps["photos"], steps["corrected"]
    assert b["mean"] < a["mean"]  # the correction lowers the colour steps at the seams
    assert f"{a['mean']:.2f} → {b['mean']:.2f}" in page  # the summary card
    assert f"<td>{a['p90']:.2f}</td><td>{b['p90']:.2f}</td>" in sec["correction"]
    assert len(_images(sec["correction"])) == 5


def test_a_model_too_big_to_embed_is_said_so(run_dir, scene):
    from o3d_seqcc.report.viewer import model_section
    from o3d_seqcc.texturing import load_textured_mesh

    tm = load_textured_mesh(run_dir / "mesh.glb")
    html_ = model_section(tm, scene.scene.views[0], scene.scene, None, None, max_faces=len(tm.faces) - 1)
    assert "<canvas" not in html_ and f"has {len(tm.faces)} faces, more than this page embeds" in html_
    assert "mesh.glb" in html_


def test_texture_writes_the_viewer_without_the_correction_sections(scene, tmp_path):
    out = tmp_path / "t"
    assert main(["-q", "texture", str(scene.root / "scene.json"), "--out", str(out), *FAST[2:]]) == 0
    page = (out / "report.html").read_text(encoding="utf-8")
    sec = _sections(page)
    assert list(sec)[:1] == ["model"] and "correction" not in sec and "table2" not in sec
    data = json.loads(_scripts(page)[1][0][1])
    assert [m["key"] for m in data["modes"]] == ["result", "photos"]


def test_t_npm_is_shown_as_its_setting_and_count_in_every_mapping_mode():
    from o3d_seqcc.errors import InputError
    from o3d_seqcc.report.page import t_npm_text
    from o3d_seqcc.report.validate import validate_report

    name = "t<sub>npm</sub>"
    assert t_npm_text({"t_npm": "auto", "t_npm_effective": 3072, "mappings": "surface"}) == \
        f"{name} = auto (1 % of a photo) = 3072 px of shared surface"
    assert t_npm_text({"t_npm": 500, "t_npm_effective": 500, "mappings": "surface"}) == f"{name} = 500 px of shared surface"
    assert t_npm_text({"t_npm": "auto", "t_npm_effective": 400, "mappings": "vertices"}) == \
        f"{name} = auto (the paper's) = 400 mappings"
    assert t_npm_text({"t_npm": 20, "t_npm_effective": 69, "mappings": "dense"}).startswith(
        f"{name} = 20 (the setting, in vertex mappings) = 69 dense mappings")
    # report.json holds the setting as given ("auto" or a number) and the count it meant
    rep = {"command": "correct", "reference": "v00", "t_npm": "auto", "t_npm_effective": 3072}
    assert validate_report(rep) is rep
    for bad in ("many", 2.5, True):
        with pytest.raises(InputError, match="'t_npm' must be an integer or \"auto\""):
            validate_report({**rep, "t_npm": bad})


def test_the_graph_is_svg_text_with_a_node_per_view_and_an_arrow_per_path_edge():
    from o3d_seqcc.report.figures import graph_svg, nice_ticks, viridis

    ticks, dec = nice_ticks(0.9934, 0.9999, 8)
    np.testing.assert_allclose(ticks, [0.994, 0.995, 0.996, 0.997, 0.998, 0.999])
    assert dec == 3
    ticks, dec = nice_ticks(0.0, 1.0)
    np.testing.assert_allclose(ticks, [0, 0.2, 0.4, 0.6, 0.8, 1.0]) and dec == 1
    assert viridis(np.array([0.0, 1.0])).tolist() == [[68, 1, 84], [253, 231, 37]]  # matplotlib's ends
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [-1.0, -1.0]])
    edges = [{"a": 0, "b": 1, "n": 10, "weight": 0.5}, {"a": 1, "b": 2, "n": 5, "weight": 0.8}]
    svg = graph_svg(xy, edges, {0: [0], 1: [1, 0], 2: [2, 1, 0]}, 0, title="ref <a> & b")
    assert svg.startswith('<svg class="graph"') and svg.endswith("</svg>") and "ref &lt;a&gt; &amp; b" in svg
    assert svg.count("<circle ") == 4 and svg.count('fill="#d62728"') == 1 and svg.count('fill="#bbb"') == 1
    arrows = svg.split('<g class="arrows" stroke="#000">')[1].split("</g>")[0]
    assert arrows.count("<line ") == 2  # 1 -> 0 and 2 -> 1 (2's path shares the edge 1 -> 0)
    assert "url(" not in svg and "http" not in svg
    assert graph_svg(xy, edges, {0: [0], 1: [1, 0], 2: [2, 1, 0]}, 0, title="ref <a> & b") == svg
