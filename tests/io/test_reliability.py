"""The user's data is sacred: output folders written as a whole, inputs never touched, hostile input refused.

One test (or more) per group of the reliability sweep: inputs deleted or overwritten, decompression
bombs, partial outputs, truncated images, stale or lost results, tracebacks instead of messages,
writes outside --out, argument checks.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import os
import shutil
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

import o3d_seqcc as sc
from o3d_seqcc import InputError
from o3d_seqcc.cli import main
from o3d_seqcc.io import output as output_mod
from o3d_seqcc.io.images import check_image_file, read_image
from o3d_seqcc.io.output import MANIFEST, check_output, output_folder
from o3d_seqcc.io.raster_checks import MAX_IMAGE_PIXELS

FAST = ["--t-npm", "50", "--atlas-size", "1024", "--no-seams", "--selection-view", "none"]


def checksums(folder: Path) -> dict[str, str]:
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("rel")
    sc.make_synthetic_scene(root / "S", n_views=5, width=160, height=120, seed=1)
    return root / "S"


@pytest.fixture
def S(scene_dir, tmp_path) -> Path:
    """A private copy of the small synthetic scene."""
    dst = tmp_path / "S"
    shutil.copytree(scene_dir, dst)
    return dst


def _visible(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if not p.name.startswith("."))


# 1-2. inputs deleted or overwritten -------------------------------------------------------------


@pytest.mark.parametrize("command", ["correct", "run"])
def test_out_equal_to_or_above_an_input_is_refused(S, tmp_path, capsys, command):
    before = checksums(S)
    assert main(["-q", command, str(S), "--out", str(S), "--overwrite", "--t-npm", "50"]) == 2
    assert "contains the input" in capsys.readouterr().err
    parent = tmp_path  # --out a parent of the scene folder
    (parent / "unrelated.txt").write_text("keep me")
    assert main(["-q", command, str(S), "--out", str(parent), "--overwrite", "--t-npm", "50"]) == 2
    assert checksums(S) == before and (parent / "unrelated.txt").read_text() == "keep me"


def test_run_save_images_never_overwrites_input_images(S):
    before = checksums(S)
    assert main(["-q", "run", str(S), "--out", str(S), "--overwrite", "--save-images", *FAST]) == 2
    assert checksums(S) == before


def test_symlinked_input_inside_out_is_refused(S, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "link").symlink_to(S)
    with pytest.raises(InputError, match="contains the input"):
        check_output(out / "link", overwrite=True, inputs=[S / "mesh.ply"])


# 3. decompression bombs and pixel budgets --------------------------------------------------------


def _png_declaring(path: Path, w: int, h: int) -> None:
    """A small valid 1x1 PNG whose IHDR is patched to declare w x h (the CRC fixed): a bomb header."""
    ok, buf = cv2.imencode(".png", np.zeros((1, 1, 3), np.uint8))
    data = bytearray(buf.tobytes())
    ihdr = 8  # after the signature: length (4) + b"IHDR" (4) + fields
    data[ihdr + 8:ihdr + 16] = struct.pack(">II", w, h)
    crc = zlib.crc32(bytes(data[ihdr + 4:ihdr + 8 + 13])) & 0xFFFFFFFF
    data[ihdr + 21:ihdr + 25] = struct.pack(">I", crc)
    path.write_bytes(bytes(data))


def test_decompression_bomb_refused_before_decoding(S, capsys):
    bomb = S / "images" / "v01.png"
    _png_declaring(bomb, 12000, 12000)
    with pytest.raises(InputError, match=r"12000x12000 = 144 Mpx, over the limit of 100 Mpx"):
        check_image_file(bomb)
    with pytest.raises(InputError, match="over the limit"):
        read_image(bomb)
    _png_declaring(bomb, 40000, 40000)  # beyond Pillow's own hard limit
    with pytest.raises(InputError, match=str(bomb)):
        check_image_file(bomb)
    doc = json.loads((S / "scene.json").read_text())
    doc["views"][1].update(width=12000, height=12000)
    (S / "scene.json").write_text(json.dumps(doc))
    assert main(["-q", "correct", str(S), "--out", str(S.parent / "o"), "--t-npm", "50"]) == 2
    assert "over the limit" in capsys.readouterr().err
    assert not (S.parent / "o").exists()


def test_max_image_pixels_option(S, capsys):
    assert main(["-q", "info", str(S), "--max-image-pixels", "1000"]) == 2
    assert "= 19200 pixels, over the limit of 1000 pixels" in capsys.readouterr().err
    assert output_mod is not None and MAX_IMAGE_PIXELS == sc.io.raster_checks.MAX_IMAGE_PIXELS == 100_000_000  # restored
    assert main(["-q", "info", str(S)]) == 0


# 4. partial outputs ------------------------------------------------------------------------------


def test_failure_after_loading_leaves_nothing_and_rerun_works(S, tmp_path, monkeypatch):
    out = tmp_path / "g"
    import o3d_seqcc.run_folder.write as rf  # RunResult.save's writer

    def boom(*a, **k):
        raise RuntimeError("disk exploded")

    monkeypatch.setattr(rf, "export_textured_mesh", boom)
    with pytest.raises(RuntimeError):
        main(["-q", "run", str(S), "--out", str(out), *FAST])
    assert not out.exists() and not [p for p in tmp_path.iterdir() if p.name.startswith(".g.")]
    monkeypatch.undo()
    assert main(["-q", "run", str(S), "--out", str(out), *FAST]) == 0
    files = json.loads((out / MANIFEST).read_text())["files"]
    assert "report.json" in files and "mesh.glb" in files


def test_interrupted_swap_is_repaired_by_the_next_run(tmp_path):
    out = tmp_path / "o"
    with output_folder(out) as st:
        (st / "a.txt").write_text("first")
    # a run killed between its two renames: the previous output aside, OUT missing, a staging folder left
    dead = 2**22 + 12345
    os.replace(out, tmp_path / f".o.o3d_seqcc-{dead}.old")
    (tmp_path / f".o.o3d_seqcc-{dead}.staging").mkdir()
    with output_folder(out, overwrite=True) as st:
        assert (out / "a.txt").read_text() == "first"  # restored before the new run writes anything
        (st / "b.txt").write_text("second")
    assert _visible(out) == ["b.txt"] and _visible(tmp_path) == ["o"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o"]


def test_killed_run_leaves_previous_output_intact(S, tmp_path):
    out = tmp_path / "k"
    assert main(["-q", "correct", str(S), "--out", str(out), "--t-npm", "50", "--no-metrics"]) == 0
    before = checksums(out)
    cmd = [sys.executable, "-m", "o3d_seqcc", "-q", "run", str(S), "--out", str(out), "--overwrite", *FAST]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        proc.wait(timeout=1.5)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    after = checksums(out)
    assert after == before or ("report.json" in after and MANIFEST in after)  # old output, or the new one whole
    assert main(["-q", "correct", str(S), "--out", str(out), "--t-npm", "50", "--no-metrics", "--overwrite"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["S", "k"]  # nothing left beside it


# 5. truncated images -----------------------------------------------------------------------------


@pytest.mark.parametrize("ext", [".jpg", ".png"])
def test_truncated_image_is_an_error_naming_the_file(S, ext, capsys):
    img = cv2.imread(str(S / "images" / "v02.png"))
    path = S / "images" / f"v02{ext}"
    cv2.imwrite(str(path), img)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(InputError, match=rf"v02\{ext} is truncated"):
        read_image(path)
    doc = json.loads((S / "scene.json").read_text())
    doc["views"][2]["image"] = f"images/v02{ext}"
    (S / "scene.json").write_text(json.dumps(doc))
    assert main(["-q", "info", str(S)]) == 2  # info refuses what correct would refuse
    assert "truncated" in capsys.readouterr().err


# 6. stale or lost results ------------------------------------------------------------------------


def test_overwrite_replaces_the_whole_previous_output(S, tmp_path):
    out = tmp_path / "r"
    assert main(["-q", "run", str(S), "--out", str(out), "--format", "glb,obj", "--save-images", *FAST]) == 0
    assert {"mesh.obj", "mesh.png", "images"} <= set(_visible(out))
    assert main(["-q", "run", str(S), "--out", str(out), "--overwrite", "--format", "glb", *FAST]) == 0
    files = set(_visible(out))
    assert "mesh.glb" in files and not files & {"mesh.obj", "mesh.png", "mesh.mtl", "images"}
    report = json.loads((out / "report.json").read_text())
    assert set(report["files"]) == {"glb", "meshlab_project", "meshlab_mesh", "report_html"}


def test_overwrite_never_replaces_a_folder_with_foreign_files(S, tmp_path, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("precious")
    assert main(["-q", "run", str(S), "--out", str(out), "--overwrite", *FAST]) == 2
    assert "did not write (notes.txt)" in capsys.readouterr().err
    assert _visible(out) == ["notes.txt"]


def test_concurrent_runs_on_one_out_the_second_fails_clearly(tmp_path):
    out = tmp_path / "c"
    lock = open(tmp_path / ".c.o3d_seqcc.lock", "w")
    fcntl.flock(lock.fileno(), fcntl.LOCK_EX)
    lock.write("4242")
    lock.flush()
    try:
        with pytest.raises(InputError, match=r"another o3d-seqcc run \(pid 4242\) is writing"):
            with output_folder(out):
                pass
    finally:
        lock.close()
    with output_folder(out) as st:  # free again
        (st / "x").write_text("1")
    assert (out / "x").read_text() == "1"


# 7. tracebacks instead of messages ---------------------------------------------------------------


def test_full_or_read_only_disk_is_a_message(S, tmp_path, monkeypatch, capsys):
    import o3d_seqcc.io.atomic as atomic
    import o3d_seqcc.io.images as images
    import o3d_seqcc.io.json_files as json_files

    real = atomic.atomic_write_bytes

    def full(path, data):
        if "report" in str(path):
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, data)

    for module in (images, json_files):  # the writers that look atomic_write_bytes up in their module
        monkeypatch.setattr(module, "atomic_write_bytes", full)
    assert main(["-q", "correct", str(S), "--out", str(tmp_path / "f"), "--t-npm", "50", "--no-metrics"]) == 2
    err = capsys.readouterr().err
    assert "cannot write the output folder" in err and "the disk is full" in err
    assert not (tmp_path / "f").exists() and sorted(p.name for p in tmp_path.iterdir()) == ["S"]
    monkeypatch.setattr(os, "access", lambda p, mode: False)
    with pytest.raises(InputError, match="read-only or no permission"):
        check_output(tmp_path / "ro")


@pytest.mark.parametrize("edit, match", [
    (lambda d: d.update(mesh=None), r"'mesh' must be a non-empty relative or absolute path string"),
    (lambda d: d["views"][0].update(width="160"), r"'width' must be a number, got '160' \(str\)"),
    (lambda d: d["views"][0].update(name="a\x00b"), "control characters"),
    (lambda d: d["views"][0].update(name="n" * 300), "300 characters long; at most 120"),
    (lambda d: d["views"][0].update(extrinsic=[[1, 2], [3]]), "'extrinsic' must be a 4x4 list of numbers"),
])
def test_bad_manifest_fields_are_messages(S, edit, match):
    doc = json.loads((S / "scene.json").read_text())
    edit(doc)
    (S / "scene.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match=match):
        sc.load_scene(S)


def test_non_utf8_manifest_and_bad_paths(S, tmp_path, capsys):
    (S / "scene.json").write_bytes(b'{"format": "o3d_seqcc.scene/1", "mesh": "\xff\xfe"}')
    with pytest.raises(InputError, match="not UTF-8"):
        sc.load_scene(S)
    (tmp_path / "afile").write_text("x")
    with pytest.raises(InputError, match="is a file, not a folder"):
        check_output(tmp_path / "afile" / "sub")
    assert main(["-q", "mappings", str(S), "--out", str(tmp_path)]) == 2
    assert "ending in .npz" in capsys.readouterr().err


def test_singular_pose_and_malformed_colmap(tmp_path):
    from o3d_seqcc.io.colmap import load as load_colmap
    from o3d_seqcc.io.rgbd_folder import read_log_trajectory

    log = tmp_path / "key.log"
    log.write_text("0 0 1\n" + "0 0 0 0\n" * 3 + "0 0 0 1\n")
    with pytest.raises(InputError, match="pose 0 is singular"):
        read_log_trajectory(log)
    (tmp_path / "cameras.txt").write_text("1 PINHOLE 64 forty-eight 1 1 1 1\n")
    (tmp_path / "images.txt").write_text("1 1 0 0 0 0 0 0 1 a.png\n\n")
    with pytest.raises(InputError, match="width and height must be integers"):
        load_colmap(tmp_path, mesh=log)
    (tmp_path / "cameras.txt").write_text("1 PINHOLE 64 48 1 1 1 1\n")
    (tmp_path / "images.txt").write_text("1 one 0 0 0 0 0 0 1 a.png\n\n")
    with pytest.raises(InputError, match="image line '1 one .*': QW: 'one' is not a number"):
        load_colmap(tmp_path, mesh=log)


def test_interrupt_during_start_up_exits_130(monkeypatch, capsys):
    import o3d_seqcc.cli as cli

    def interrupted(**_):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "build_parser", interrupted)
    assert cli.main(["info", "x"]) == 130
    assert "interrupted" in capsys.readouterr().err


# 8. writes outside --out -------------------------------------------------------------------------


def test_symlinked_out_is_followed_and_images_symlink_not_written_through(S, tmp_path, capsys):
    target = tmp_path / "disk" / "results"
    target.mkdir(parents=True)
    link = tmp_path / "out"
    link.symlink_to(target, target_is_directory=True)
    assert main(["-q", "run", str(S), "--out", str(link), *FAST]) == 0
    assert link.is_symlink() and (target / "report.json").is_file()
    assert len(sc.load_scene(link / "project.mlp").views) == 5  # the project loads through the link
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "keep.png").write_bytes(b"not ours")
    shutil.rmtree(target / "images", ignore_errors=True)
    (target / "images").symlink_to(elsewhere, target_is_directory=True)
    # a link the user put into the output is not ours: --overwrite refuses instead of removing it
    assert main(["-q", "run", str(S), "--out", str(link), "--overwrite", "--save-images", *FAST]) == 2
    assert "did not write (images)" in capsys.readouterr().err
    assert _visible(elsewhere) == ["keep.png"] and (elsewhere / "keep.png").read_bytes() == b"not ours"
    assert (target / "images").is_symlink()
    (target / "images").unlink()
    assert main(["-q", "run", str(S), "--out", str(link), "--overwrite", "--save-images", *FAST]) == 0
    assert not (target / "images").is_symlink() and len(_visible(target / "images")) == 5
    assert sorted(p.name for p in tmp_path.iterdir()) == ["S", "disk", "elsewhere", "out"]
    assert sorted(p.name for p in (tmp_path / "disk").iterdir()) == ["results"]


# 9. argument checks ------------------------------------------------------------------------------


def test_argument_checks_before_work(S, tmp_path, capsys):
    assert main(["-q", "correct", str(S), "--out", str(tmp_path / "o"), "--t-npm", "-5"]) == 2
    assert "--t-npm: give 'auto' or a positive integer" in capsys.readouterr().err
    assert main(["-q", "run", str(S), "--out", str(tmp_path / "o"), "--reference", "nope"]) == 2
    assert "unknown view 'nope'" in capsys.readouterr().err
    assert main(["run", str(S), "--out", str(tmp_path / "o"), "--method", "best", "-q"]) == 2  # -q after the command
    assert "invalid choice" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_a_warning_is_printed_once(S, tmp_path, capsys):
    assert main(["run", str(S), "--out", str(tmp_path / "w"), *FAST[2:], "--t-npm", "100000", "--method", "none"]) == 0
    err = capsys.readouterr().err
    assert err.count("no colour-correction path") <= 1


# found by benchmarks/hostile_inputs.py ----------------------------------------------------------


@pytest.mark.parametrize("argv, match", [
    (["mappings", "{S}", "--out", "{T}/m.npz", "--max-angle", "-5"], "max_angle"),
    (["mappings", "{S}", "--out", "{T}/m.npz", "--depth-tol", "-1"], "depth_tol"),
    (["mappings", "{S}", "--out", "{T}/m.npz", "--occlusion-tol", "nan"], "occlusion_tol"),
    (["texture", "{S}", "--out", "{T}/o", "--smoothness", "-1"], "smoothness"),
    (["run", "{S}", "--out", "{T}/o", "--leveling-smoothness", "-1"], "leveling_smoothness"),
    (["texture", "{S}", "--out", "{T}/o", "--atlas-size", "100000"], "at most 16384"),
    (["evaluate", "{S}", "--blur", "-1"], "--blur"),
    (["correct", "{S}", "--out", "{T}/o", "--depth-scale", "-1"], "--depth-scale"),
    (["synthetic", "{T}/syn", "--width", "100000", "--height", "100000"], "over the limit"),
])
def test_bad_option_values_are_messages_not_tracebacks(S, tmp_path, capsys, argv, match):
    argv = [a.format(S=S, T=tmp_path) for a in argv]
    assert main(["-q", *argv]) == 2
    assert match in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["S"]


def test_json_report_never_replaces_an_input(S, capsys):
    before = checksums(S)
    assert main(["-q", "evaluate", str(S), "--json", str(S / "scene.json")]) == 2
    assert "would replace it" in capsys.readouterr().err
    assert main(["-q", "seams", str(S / "mesh.ply"), "--json", str(S / "mesh.ply")]) == 2
    assert checksums(S) == before


def test_interrupt_while_open3d_initialises_exits_130(monkeypatch, capsys):
    import o3d_seqcc.cli as cli

    def interrupted(args):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as e:
            raise ImportError("initialization failed") from e

    parser = cli.build_parser()
    monkeypatch.setattr(cli, "build_parser", lambda **_: parser)
    args = parser.parse_args(["info", "x"])
    monkeypatch.setattr(args, "func", interrupted, raising=False)
    monkeypatch.setattr(parser, "parse_args", lambda argv=None: args)
    assert cli.main(["info", "x"]) == 130
    assert "interrupted" in capsys.readouterr().err
