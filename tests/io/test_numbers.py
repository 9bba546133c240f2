"""Numbers read from input files (issue 38): NaN, inf and denormals are an InputError naming the file and field.

A denormal such as 1e-320 parses, passes ``> 0`` and then overflows what divides by it: a depth_scale of 1e-320
made every depth inf with a numpy warning as the only sign.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import o3d_seqcc as sc
from o3d_seqcc import InputError, load_scene
from o3d_seqcc._shared.numbers import TINY, check_numbers, is_finite_normal, parse_number
from o3d_seqcc.cli import main
from o3d_seqcc.io.meshlab import save_mlp


@pytest.mark.parametrize("token", ["nan", "inf", "-inf", "1e999", "1e-320", "-4e-310", "x", ""])
def test_parse_number_refuses_what_is_not_a_finite_normal_number(token):
    with pytest.raises(InputError, match=r"^cams\.txt: line 3: f: .* (is not a number|is not a finite normal)"):
        parse_number(token, "cams.txt: line 3: f")


def test_parse_number_and_check_numbers_keep_every_normal_number():
    for x in (0.0, -0.0, TINY, -TINY, 1e-300, 1.0, 1e300):
        assert is_finite_normal(x) and parse_number(repr(x), "w") == x
    a = np.array([[1.0, 0.0, 1e-17], [TINY, -1e300, 5.0]])
    np.testing.assert_array_equal(check_numbers(a, "K"), a)
    a[1, 0] = TINY / 4  # denormal
    with pytest.raises(InputError, match=r"^K: 5\.56\d*e-309 at \[1, 0\] is not a finite normal number"):
        check_numbers(a, "K")
    with pytest.raises(InputError, match=r"^K: nan at \[0, 2\]"):
        check_numbers([[1, 2, np.nan]], "K")


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    return sc.make_synthetic_scene(tmp_path_factory.mktemp("numbers") / "R", n_views=3, width=48, height=36,
                                   seen_only=True, photometric="none")


def _edited_scene_json(room, tmp_path, edit):
    d = json.loads((room.root / "scene.json").read_text())
    for v in d["views"]:  # absolute paths: the copy refers to the room's files
        for k in ("image", "depth"):
            if v.get(k):
                v[k] = str((room.root / v[k]).resolve())
    d["mesh"] = str((room.root / d["mesh"]).resolve())
    edit(d)
    p = tmp_path / "scene.json"
    p.write_text(json.dumps(d))
    return p


@pytest.mark.parametrize("field, edit, match", [
    ("depth_scale", lambda d: d["views"][1].update(depth_scale=1e-320),
     r"view 'v01': depth_scale must be between 1e-06 and 1e\+09 .* got 1e-320"),
    ("depth_scale", lambda d: d["views"][1].update(depth_scale=1e300), r"view 'v01': depth_scale must be between"),
    ("intrinsic", lambda d: d["views"][0]["intrinsic"][0].__setitem__(1, 1e-320),
     r"view 'v00': intrinsic: 1e-320 at \[0, 1\] is not a finite normal number"),
    ("extrinsic", lambda d: d["views"][2]["extrinsic"][1].__setitem__(3, -3e-315),
     r"view 'v02': extrinsic: -3e-315 at \[1, 3\] is not a finite normal number"),
])
def test_scene_json_names_the_file_the_view_and_the_field(room, tmp_path, field, edit, match):
    p = _edited_scene_json(room, tmp_path, edit)
    with pytest.raises(InputError, match=rf"^{p}: {match}"):
        load_scene(p)


def test_cli_depth_scale_and_the_front_door(room, tmp_path, capsys):
    assert main(["info", str(room.root), "--depth-scale", "1e-320"]) == 2
    assert "--depth-scale must be between 1e-06 and 1e+09 depth units per metre" in capsys.readouterr().err
    import open3d as o3d

    scene = load_scene(room.root)
    mesh = o3d.io.read_triangle_mesh(str(scene.mesh))
    cams = ([v.intrinsic for v in scene.views], [v.extrinsic for v in scene.views])
    with pytest.raises(InputError, match="depth_scale must be a positive number of depth units per metre, between"):
        sc.texture_mesh(mesh, [v.load_image() for v in scene.views], cams, depth_scale=1e-320)


def test_a_meshlab_project_names_the_camera_field(room, tmp_path):
    p = save_mlp(load_scene(room.root), tmp_path / "p.mlp")
    text = p.read_text()
    start = text.index('FocalMm="') + len('FocalMm="')
    p.write_text(text[:start] + "1e-320" + text[text.index('"', start):])
    with pytest.raises(InputError, match=r"VCGCamera FocalMm: 1e-320 at \[0\] is not a finite normal number"):
        load_scene(p)
