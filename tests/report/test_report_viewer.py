"""The report's 3D viewer, in headless Debian Chromium: it draws the model, offline, and its controls work.

``o3d-seqcc -q demo`` writes the report (and prints nothing); the page is opened in Chromium over
the DevTools protocol (tests/_chromium.py). The canvas, set to a photo's aspect, must show what
our own ray caster renders from the same camera; the texture buttons, orbit and zoom must change
the picture; nothing may be fetched but the page itself and its inline data. With
``O3D_SEQCC_SCREENSHOT_DIR`` set, the viewer's and the close-ups' sections are also written there as
screenshots (docs/report_viewer.png and docs/report_correction.png come from
``O3D_SEQCC_SCREENSHOT_DIR=docs python -m pytest tests/report/test_report_viewer.py``).
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from o3d_seqcc.cli import main
from o3d_seqcc.io.load import load_scene
from o3d_seqcc.evaluation.render import render_textured, resized_view
from o3d_seqcc.texturing import load_textured_mesh

from _chromium import CHROMIUM, Browser

pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is not installed (./dev.sh setup)")

W, H = 640, 480


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("viewer") / "demo"
    return out


def _decode(png: bytes) -> np.ndarray:
    return cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[..., ::-1].astype(np.float64)


def _save(name: str, png: bytes) -> None:
    where = os.environ.get("O3D_SEQCC_SCREENSHOT_DIR")
    if where:
        Path(where).mkdir(parents=True, exist_ok=True)
        (Path(where) / name).write_bytes(png)


def test_quiet_demo_prints_nothing_and_writes_the_viewer(demo, capfd):
    assert main(["-q", "demo", "--out", str(demo), "--views", "10", "--t-npm", "200"]) == 0
    out, err = capfd.readouterr()
    assert (out, err) == ("", "")
    page = (demo / "report.html").read_text(encoding="utf-8")
    assert '<div id="o3d-viewer"' in page and 'id="o3d-viewer-data"' in page
    # the graph threshold one way everywhere: the setting (vertex units) and its count in the demo's dense mappings
    rep = json.loads((demo / "run" / "report.json").read_text())
    eff = rep["correction"]["t_npm"]
    assert rep["correction"]["settings"]["t_npm"] == 200 and eff != 200
    assert f"t<sub>npm</sub> = 200 (the setting, in vertex mappings) = {eff} dense mappings" in page
    assert f"<tr><th>t_npm</th><td>200</td></tr><tr><th>t_npm_effective</th><td>{eff}</td></tr>" in page
    # the scene it ran on, named in the subtitle and the settings
    scene = str((demo / "scene" / "scene.json").resolve())
    assert rep["scene"] == scene and f"<tr><th>scene</th><td>{scene}</td></tr>" in page


def _canvas_shot(page) -> np.ndarray:
    page.eval("(() => { const c = document.querySelector('#o3d-viewer canvas');"
              f" c.style.width = '{W}px'; c.style.height = '{H}px'; c.scrollIntoView();"
              " window.dispatchEvent(new Event('resize')); return true; })()")
    page.eval("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(true))))")
    r = page.eval("(() => { const b = document.querySelector('#o3d-viewer canvas').getBoundingClientRect();"
                  " return [b.left + window.scrollX, b.top + window.scrollY]; })()")
    png = page.screenshot(clip={"x": r[0], "y": r[1], "width": W, "height": H})
    return png


def test_the_viewer_shows_a_loading_notice_until_the_model_is_drawn(demo):
    """Before the viewer's script has drawn (a capture with --virtual-time-budget, a slow machine) the canvas carries
    a notice, not an empty grey box; once drawn the notice is gone."""
    uri = (demo / "run" / "report.html").resolve().as_uri()
    notice = "getComputedStyle(document.querySelector('#o3d-viewer .viewer-loading'))"
    with Browser(1280, 900) as b:
        page = b.open(uri, scripts=False)
        assert page.eval(f"{notice}.display") == "flex"
        assert page.eval("document.querySelector('#o3d-viewer .viewer-loading').textContent") == "Loading the 3D model…"
        page = b.open(uri)
        assert page.wait_for("document.getElementById('o3d-viewer').dataset.state === 'drawn'", timeout=90)
        assert page.eval(f"{notice}.display") == "none"


def test_the_viewer_draws_the_model_offline_and_responds(demo):
    run = demo / "run"
    page_html = (run / "report.html").read_text(encoding="utf-8")
    first = re.search(r"The first view is the camera of ([^.<]+)\.", page_html).group(1)
    rep = json.loads((run / "report.json").read_text())
    scene = load_scene(demo / "scene" / "scene.json")
    view = scene.views[scene.names.index(first)]
    # our ray-cast render of mesh.glb (rotated back into the cameras' frame) from the viewer's first camera
    R = np.asarray(rep["export"]["orientation"]["rotation"])
    tm = load_textured_mesh(run / "mesh.glb")
    from dataclasses import replace

    tm = replace(tm, vertices=tm.vertices @ R, normals=None)
    ours = render_textured(tm, resized_view(view, W, H)).astype(np.float64)
    other = render_textured(tm, resized_view(scene.views[(scene.names.index(first) + 3) % len(scene.views)], W, H))

    with Browser(1280, 900) as b:
        page = b.open((run / "report.html").resolve().as_uri())
        state = page.wait_for("document.getElementById('o3d-viewer').dataset.state !== 'loading'"
                              " && document.getElementById('o3d-viewer').dataset.state", timeout=90)
        assert state == "drawn", (state, page.console[-5:])
        # offline: the page asked for itself and its inline data only
        assert page.requests and all(u.startswith(("file:", "data:", "blob:")) for u in page.requests), page.requests
        for sid, name in (("model", "report_viewer.png"), ("correction", "report_correction.png")):
            r = page.eval(f"(() => {{ const b = document.getElementById('{sid}').getBoundingClientRect();"
                          " return [b.left + window.scrollX, b.top + window.scrollY, b.width, b.height]; })()")
            _save(name, page.screenshot(clip={"x": r[0], "y": r[1], "width": r[2], "height": r[3]}))
        shot = _decode(_canvas_shot(page))
        assert shot.shape == (H, W, 3)
        # the canvas draws the model where the camera sees it: close to our render, far from another view's
        hit = (ours < 250).any(axis=2) | (ours > 5).any(axis=2)
        bg = np.abs(shot - [242, 242, 242]).max(axis=2) <= 6
        assert (~bg).mean() > 0.5, (~bg).mean()  # not the empty background
        d_same = np.abs(shot - ours)[hit & ~bg].mean()
        d_other = np.abs(shot - other)[hit & ~bg].mean()
        assert d_same < 25 and d_same < 0.6 * d_other, (d_same, d_other)

        def mode(key: str) -> np.ndarray:
            page.eval(f"document.querySelector('input[name=\"o3d-mode\"][value=\"{key}\"]').click(), true")
            assert page.wait_for("document.getElementById('o3d-viewer').dataset.mode === '" + key + "'"
                                 " && document.getElementById('o3d-viewer').dataset.state === 'drawn'", timeout=60)
            return _decode(_canvas_shot(page))

        photos, corrected, selection = mode("photos"), mode("corrected"), mode("selection")
        back = mode("result")
        assert np.abs(back - shot).mean() < 1.0  # the same picture again
        # the atlas as written, decoded on demand: the same picture, and at least as much of the render's structure
        full_h, full_w = tm.texture.shape[:2]
        assert re.search(rf'value="full"> full resolution \({full_w}×{full_h} texels, as written\)', page_html)
        full = mode("full")
        assert np.abs(full - shot).mean() < 4.0

        def lap_corr(img: np.ndarray) -> float:
            a, b = (cv2.Laplacian(x.mean(axis=2), cv2.CV_64F)[hit & ~bg] for x in (img, ours))
            return float(np.corrcoef(a, b)[0, 1])

        assert lap_corr(full) >= lap_corr(shot) - 0.01, (lap_corr(full), lap_corr(shot))
        back = mode("result")
        # as taken the photos differ from the result much more than the corrected ones do
        d_photos, d_corr = np.abs(photos - shot).mean(), np.abs(corrected - shot).mean()
        assert d_photos > 2.0 * d_corr and d_photos > 5, (d_photos, d_corr)
        # selection colours: saturated patches, unlike the texture
        sat = selection.max(axis=2) - selection.min(axis=2)
        assert np.median(sat[~bg]) > 60 and np.abs(selection - shot).mean() > 20
        # orbit (drag) and zoom (wheel) move the camera
        r = page.eval("(() => { const b = document.querySelector('#o3d-viewer canvas').getBoundingClientRect();"
                      " return [b.left + b.width / 2, b.top + b.height / 2]; })()")
        page.drag(r[0], r[1], r[0] + 150, r[1] + 40)
        orbited = _decode(_canvas_shot(page))
        assert np.abs(orbited - back).mean() > 8
        r = page.eval("(() => { const b = document.querySelector('#o3d-viewer canvas').getBoundingClientRect();"
                      " return [b.left + b.width / 2, b.top + b.height / 2]; })()")
        page.wheel(r[0], r[1], -600)
        zoomed = _decode(_canvas_shot(page))
        assert np.abs(zoomed - orbited).mean() > 5
        assert not [m for m in page.console if m.startswith("exception")], page.console
