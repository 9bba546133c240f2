"""Nothing read back from an output folder's manifest is trusted (issue 38).

A hostile user edits ``.o3d_seqcc.json`` of an earlier output to list a file outside the folder, an
absolute path or a path through a symbolic link: ``--overwrite`` must refuse the folder, name the
entry, and touch no file inside or outside it.
"""

from __future__ import annotations

import json
import os

import pytest

import o3d_seqcc as sc
from o3d_seqcc import InputError
from o3d_seqcc.cli import main
from o3d_seqcc.io.manifest import MANIFEST, own_files, untrusted_entry
from o3d_seqcc.io.output import check_output, output_folder


def _earlier_output(out):
    with output_folder(out, command="run") as st:
        (st / "mesh.obj").write_text("o mesh\n")
        (st / "views").mkdir()
        (st / "views" / "v00.png").write_bytes(b"png")
    return out


def _tamper(out, extra):
    data = json.loads((out / MANIFEST).read_text())
    data["files"] += extra
    (out / MANIFEST).write_text(json.dumps(data))


def _snapshot(root):
    return sorted((p.relative_to(root).as_posix(), p.read_bytes() if p.is_file() and not p.is_symlink() else None)
                  for p in root.rglob("*"))


@pytest.mark.parametrize("entry, why", [
    ("../victim.txt", "leaves the folder"),
    ("views/../../victim.txt", "leaves the folder"),
    ("{victim}", "an absolute path"),
    ("./mesh.obj", "not normalised"),
    ("views//v00.png", "not normalised"),
    ("link/victim.txt", "passes through the symbolic link link"),
    ("", "not a file name"),
    (7, "not a file name"),
])
def test_a_tampered_manifest_makes_the_folder_foreign(tmp_path, entry, why):
    outside = tmp_path / "outside"
    outside.mkdir()
    victim = outside / "victim.txt"
    victim.write_text("the user's data")
    out = _earlier_output(tmp_path / "work" / "out")
    (tmp_path / "work" / "victim.txt").write_text("a neighbour's data")
    os.symlink(outside, out / "link")
    if entry == "{victim}":
        entry = str(victim)
    _tamper(out, [entry, "link"])
    before = _snapshot(tmp_path)
    with pytest.raises(InputError, match=why) as e:
        check_output(out, overwrite=True)
    assert repr(entry)[:40] in str(e.value) and MANIFEST in str(e.value)
    with pytest.raises(InputError, match=why):
        with output_folder(out, overwrite=True, command="run") as st:
            (st / "mesh.obj").write_text("o new\n")
    assert _snapshot(tmp_path) == before  # nothing inside or outside the folder was touched


def test_the_cli_refuses_and_names_the_entry(tmp_path, capsys):
    scene = sc.make_synthetic_scene(tmp_path / "scene", n_views=2, width=32, height=24, seed=0, cell_size=0.5)
    out = _earlier_output(tmp_path / "out")
    (tmp_path / "victim.txt").write_text("the user's data")
    _tamper(out, ["../victim.txt"])
    rc = main(["-q", "run", str(scene.root), "--out", str(out), "--overwrite"])
    assert rc != 0 and "'../victim.txt'" in capsys.readouterr().err
    assert (tmp_path / "victim.txt").read_text() == "the user's data" and (out / "mesh.obj").is_file()
    # the demo writes OUT/run, OUT/report.html and OUT/demo_summary.json: checked before it generates anything
    demo = tmp_path / "demo"
    _earlier_output(demo / "run")
    _tamper(demo / "run", ["../../victim.txt"])
    assert main(["-q", "demo", "--out", str(demo)]) != 0 and "'../../victim.txt'" in capsys.readouterr().err
    assert not (demo / "scene").exists() and (tmp_path / "victim.txt").is_file()


def test_a_clean_manifest_is_still_ours(tmp_path):
    out = _earlier_output(tmp_path / "out")
    assert own_files(out) == {"mesh.obj", "views/v00.png"}
    assert untrusted_entry(out, "views/v00.png") == "" and untrusted_entry(out, "empty/") == ""
    with output_folder(out, overwrite=True, command="run") as st:
        (st / "mesh.obj").write_text("o new\n")
    assert (out / "mesh.obj").read_text() == "o new\n" and not (out / "views").exists()
