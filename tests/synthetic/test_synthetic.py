"""Tests of o3d_seqcc.synthetic (the synthetic room generator) and the demo / synthetic CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from o3d_seqcc import load_scene
from o3d_seqcc.io.depth import read_depth
from o3d_seqcc.io.images import read_image
from o3d_seqcc.errors import InputError
from o3d_seqcc.synthetic import ALBEDO_RANGE, apply_photometric, load_synthetic, make_synthetic_scene
from o3d_seqcc.synthetic.room import ROOM

W, H, N = 160, 120, 6


@pytest.fixture(scope="module")
def syn(tmp_path_factory):
    return make_synthetic_scene(tmp_path_factory.mktemp("syn") / "s", n_views=N, width=W, height=H, seed=3)


@pytest.fixture(scope="module")
def syn_none(tmp_path_factory):
    return make_synthetic_scene(
        tmp_path_factory.mktemp("syn_none") / "s", n_views=3, width=W, height=H, seed=3, photometric="none", cell_size=0.2
    )


def _pixel_rays(view):
    K, R, t = view.intrinsic, view.rotation, view.translation
    u, v = np.meshgrid(np.arange(view.width, dtype=float), np.arange(view.height, dtype=float))
    d_cam = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1)
    return -R.T @ t, d_cam @ R  # origin, (H, W, 3) world directions with camera z = 1


def _project(view, pts):
    x = pts @ view.rotation.T + view.translation
    uv = x[:, :2] / x[:, 2:3] * np.diag(view.intrinsic)[:2] + view.intrinsic[:2, 2]
    return uv, x[:, 2]


# ------------------------------------------------------------------ files and loading


def test_layout_and_load_scene(syn):
    root = syn.root
    scene = load_scene(root / "scene.json")  # validates every file and image size
    assert scene == syn.scene
    assert scene.names == [f"v{i:02d}" for i in range(N)]
    mesh = scene.load_mesh()
    assert len(mesh.faces) == syn.metadata["n_faces"]
    assert max(b for _, b in syn.face_groups.values()) == len(mesh.faces)
    assert {"room", "table", "cabinet", "sideboard"} <= set(syn.face_groups)
    for v in scene.views:
        assert v.depth is not None and v.depth_scale == 1000.0
        assert v.load_image().shape == (H, W, 3) and v.load_image().dtype == np.uint8
        assert v.intrinsic[0, 0] == pytest.approx(0.8 * W)
        assert v.intrinsic[:2, 2] == pytest.approx([(W - 1) / 2, (H - 1) / 2])
        assert 1.2 <= v.center[2] <= 1.7
        assert np.all(v.center > 0) and np.all(v.center < ROOM)
        assert syn.load_face_ids(v.name).shape == (H, W) and syn.load_face_ids(v.name).dtype == np.int32
        assert syn.load_points(v.name).shape == (H, W, 3) and syn.load_points(v.name).dtype == np.float32
    # room normals point inwards: the room shell's face normals point towards the room centre
    a, b = syn.face_groups["room"]
    fn = mesh.face_normals[a:b]
    centroid = mesh.vertices[mesh.faces[a:b]].mean(1)
    assert np.all(np.einsum("ij,ij->i", fn, np.array(ROOM) / 2 - centroid) > 0)
    assert np.allclose(np.linalg.norm(mesh.vertex_normals, axis=1), 1.0)


def test_load_synthetic_round_trip(syn):
    again = load_synthetic(syn.root)
    assert again.scene == syn.scene
    assert again.transforms == syn.transforms
    assert again.face_groups == syn.face_groups
    assert again.gt_images == syn.gt_images and again.points == syn.points and again.face_ids == syn.face_ids
    meta = json.loads((syn.root / "synthetic.json").read_text())
    assert [v["photometric"] for v in meta["views"]] == [syn.transforms[n] for n in syn.scene.names]


def test_load_synthetic_rejects_other_folders(tmp_path):
    with pytest.raises(InputError, match="synthetic.json"):
        load_synthetic(tmp_path)


# ------------------------------------------------------------------ geometry


def test_depth_agrees_with_mesh(syn):
    mesh = syn.scene.load_mesh()
    fnorm = mesh.face_normals
    for v in syn.scene.views:
        face = syn.load_face_ids(v.name)
        hit = face >= 0
        assert hit.mean() > 0.99  # closed room: (almost) every ray hits
        depth = v.load_depth()
        o, d = _pixel_rays(v)
        f = face[hit]
        n, p0 = fnorm[f], mesh.vertices[mesh.faces[f, 0]]
        # ray / plane of the recorded face: camera z along the ray (direction has z = 1)
        z = np.einsum("ij,ij->i", p0 - o, n) / np.einsum("ij,ij->i", d[hit], n)
        err = np.abs(depth[hit] - z)
        assert np.median(err) < 0.01
        assert np.quantile(err, 0.99) < 0.002  # only the millimetre quantisation
        # the hit point lies inside the recorded triangle (barycentric test)
        q = o + z[:, None] * d[hit]
        tri = mesh.vertices[mesh.faces[f]]
        e1, e2, w = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], q - tri[:, 0]
        d11, d12, d22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
        w1, w2 = (w * e1).sum(1), (w * e2).sum(1)
        den = d11 * d22 - d12**2
        b1, b2 = (d22 * w1 - d12 * w2) / den, (d11 * w2 - d12 * w1) / den
        inside = (b1 > -1e-3) & (b2 > -1e-3) & (b1 + b2 < 1 + 1e-3)
        assert inside.mean() > 0.999


def test_points_consistent_with_camera(syn):
    mesh = syn.scene.load_mesh()
    for v in syn.scene.views:
        face = syn.load_face_ids(v.name)
        pts = syn.load_points(v.name).astype(np.float64)
        hit = face >= 0
        assert np.all(np.isfinite(pts[hit])) and np.all(np.isnan(pts[~hit]))
        uv, z = _project(v, pts[hit])
        rows, cols = np.nonzero(hit)
        assert np.abs(uv - np.stack([cols, rows], 1)).max() < 0.01
        assert np.abs(z - v.load_depth()[hit]).max() < 0.0006  # depth PNG is in mm
        # points lie on the plane of their face
        f = face[hit]
        dist = np.einsum("ij,ij->i", pts[hit] - mesh.vertices[mesh.faces[f, 0]], mesh.face_normals[f])
        assert np.abs(dist).max() < 1e-4


def test_furniture_occludes_walls(syn):
    """Some view sees furniture; along those rays the room shell is farther away (occluded wall)."""
    a, b = syn.face_groups["room"]
    n_occluding = 0
    for v in syn.scene.views:
        face = syn.load_face_ids(v.name)
        furn = (face >= 0) & ~((face >= a) & (face < b))
        if not furn.any():
            continue
        o, d = _pixel_rays(v)
        dd = d[furn]
        # exit distance of the ray from the room box (slab method from the inside)
        with np.errstate(divide="ignore"):
            t_exit = np.min(np.where(dd > 0, (np.array(ROOM) - o) / dd, np.where(dd < 0, -o / dd, np.inf)), axis=1)
        depth = v.load_depth()[furn]
        n_occluding += int((t_exit > depth + 0.05).sum())
    assert n_occluding > 100


def test_consecutive_views_overlap_far_views_do_not(syn):
    seen = []
    for v in syn.scene.views:
        f = syn.load_face_ids(v.name)
        seen.append(set(np.unique(f[f >= 0]).tolist()))
    # N = 6 views 25 deg apart: an arc centred on view 0, ring order 0, 1, 2, 3 | 4, 5 (= -2, -1)
    ends = (N // 2, N // 2 + 1)
    for i in range(N):
        j = (i + 1) % N
        if (i, j) == ends:
            continue
        assert len(seen[i] & seen[j]) > 0.2 * min(len(seen[i]), len(seen[j])), (i, j)
    assert len(seen[ends[0]] & seen[ends[1]]) == 0  # the ring does not see everything from everywhere
    # the unchanged reference view 0 is in the middle of the chain: every view within N // 2 steps
    yaw = np.array([v["yaw_deg"] for v in syn.metadata["views"]])
    off = (yaw - yaw[0] + 180.0) % 360.0 - 180.0
    assert np.all(np.abs(off) <= 25.0 * (N // 2) + 14.0)  # + jitter of both views
    assert (off > 10).sum() >= 2 and (off < -10).sum() >= 2


def test_ring_slots_put_view_0_in_the_middle():
    from o3d_seqcc.synthetic import ring_slots

    assert ring_slots(6).tolist() == [0, 1, 2, 3, -2, -1]
    assert ring_slots(12).tolist() == [0, 1, 2, 3, 4, 5, 6, -5, -4, -3, -2, -1]
    assert ring_slots(1).tolist() == [0]


def test_gt_colour_is_view_independent(syn):
    """The same surface point has the same ground-truth colour in two views."""
    v0 = syn.scene.views[0]
    pts1 = syn.load_points(1).reshape(-1, 3).astype(np.float64)
    face1 = syn.load_face_ids(1).ravel()
    gt0, gt1 = syn.load_gt(0).astype(float), syn.load_gt(1).reshape(-1, 3).astype(float)
    face0 = syn.load_face_ids(0)
    ok = face1 >= 0
    uv, z = _project(v0, pts1[ok])
    c, r = np.rint(uv[:, 0]).astype(int), np.rint(uv[:, 1]).astype(int)
    inside = (z > 0) & (c >= 0) & (c < v0.width) & (r >= 0) & (r < v0.height)
    idx = np.flatnonzero(ok)[inside]
    c, r, subpix = c[inside], r[inside], uv[inside]
    same_face = face0[r, c] == face1[idx]
    assert same_face.sum() > 500
    # compare with a bilinear sample of view 0 at the exact projection
    from scipy.ndimage import map_coordinates

    uvs = subpix[same_face]
    col0 = np.stack([map_coordinates(gt0[..., k], [uvs[:, 1], uvs[:, 0]], order=1) for k in range(3)], 1)
    diff = np.abs(col0 - gt1[idx[same_face]])
    assert np.median(diff) < 6.0


def test_textures_are_varied(syn):
    g = np.concatenate([syn.load_gt(i).reshape(-1, 3) for i in range(N)]).astype(float)
    lum = g.mean(1)
    # realistic albedo: textures span ALBEDO_RANGE = [0.03, 0.8] (8 to 204 in 8 bits)
    lo, hi = ALBEDO_RANGE
    assert g.min() >= np.floor(255 * lo) - 1 and g.max() <= np.ceil(255 * hi) + 1
    assert np.quantile(lum, 0.05) < 40 and np.quantile(lum, 0.95) > 150
    sat = g.max(1) - g.min(1)
    assert np.quantile(sat, 0.9) > 75


# ------------------------------------------------------------------ photometry


def _reference_transform(gt_u8, p):
    """Independent re-implementation of the documented camera model."""
    x = gt_u8.astype(np.float64) / 255.0
    out = np.empty_like(x)
    for c in range(3):
        y = np.clip(x[..., c] * p["gain"] * p["white_balance"][c], 0, 1) ** p["gamma"][c]
        s = p["s_curve"]
        out[..., c] = (1 - s) * y + s * (3 * y**2 - 2 * y**3)
    return np.rint(np.clip(out, 0, 1) * 255)


def test_camera_photometric_reproducible(syn):
    names = syn.scene.names
    assert syn.transforms[names[0]] == {"gain": 1.0, "white_balance": [1.0] * 3, "gamma": [1.0] * 3, "s_curve": 0.0}
    assert np.array_equal(syn.scene.views[0].load_image(), syn.load_gt(0))
    diffs = []
    for i, name in enumerate(names):
        p = syn.transforms[name]
        assert 0.6 <= p["gain"] <= 1.6 and 0 <= p["s_curve"] <= 0.5
        assert all(0.8 <= w <= 1.2 for w in p["white_balance"]) and all(0.65 <= g <= 1.5 for g in p["gamma"])
        img = syn.scene.views[i].load_image().astype(float)
        gt = syn.load_gt(i)
        assert np.abs(_reference_transform(gt, p) - img).max() <= 1
        assert np.abs(np.rint(apply_photometric(gt, p) * 255) - img).max() <= 1
        diffs.append(np.abs(img - gt).mean())
    assert diffs[0] == 0 and max(diffs[1:]) > 5  # the changes are real


def test_apply_photometric_dtypes():
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (4, 5, 3), dtype=np.uint8)
    p = {"gain": 1.3, "white_balance": [0.9, 1.0, 1.1], "gamma": [0.8, 1.0, 1.4], "s_curve": 0.3}
    a = apply_photometric(img, p)
    b = apply_photometric(img.astype(np.uint16) * 257, p)
    c = apply_photometric(img / 255.0, p)
    assert a.dtype == np.float64 and a.min() >= 0 and a.max() <= 1
    assert np.allclose(a, b) and np.allclose(a, c)
    ident = {"gain": 1.0, "white_balance": [1, 1, 1], "gamma": [1, 1, 1], "s_curve": 0.0}
    assert np.allclose(apply_photometric(img, ident) * 255, img)


def test_photometric_none(syn_none):
    for i, name in enumerate(syn_none.scene.names):
        assert np.array_equal(syn_none.scene.views[i].load_image(), syn_none.load_gt(i))
        assert syn_none.transforms[name]["gain"] == 1.0


# ------------------------------------------------------------------ determinism, overwrite, bad options


def _tree_bytes(root):
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_deterministic_for_a_seed(tmp_path):
    kw = dict(n_views=3, width=64, height=48, cell_size=0.25)
    make_synthetic_scene(tmp_path / "a", seed=7, **kw)
    make_synthetic_scene(tmp_path / "b", seed=7, **kw)
    make_synthetic_scene(tmp_path / "c", seed=8, **kw)
    a, b, c = _tree_bytes(tmp_path / "a"), _tree_bytes(tmp_path / "b"), _tree_bytes(tmp_path / "c")
    assert a.keys() == b.keys() == c.keys()
    assert a == b
    assert a["images/v01.png"] != c["images/v01.png"]
    assert a["scene.json"] != c["scene.json"]


def test_overwrite_protection(tmp_path):
    out = tmp_path / "s"
    kw = dict(width=48, height=32, cell_size=0.3)
    make_synthetic_scene(out, n_views=4, **kw)
    with pytest.raises(InputError, match="not empty"):
        make_synthetic_scene(out, n_views=2, **kw)
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "keep.txt").write_text("x")
    with pytest.raises(InputError, match="overwrite"):
        make_synthetic_scene(tmp_path / "other", n_views=2, **kw)
    s2 = make_synthetic_scene(out, n_views=2, overwrite=True, **kw)
    assert s2.scene.names == ["v00", "v01"]
    assert not (out / "images" / "v03.png").exists() and not (out / "points" / "v03.npy").exists()
    load_scene(out)
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(InputError, match="file"):
        make_synthetic_scene(f, n_views=2, **kw)


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"photometric": "film"}, "photometric"),
        ({"n_views": 0}, "n_views"),
        ({"width": 4}, "width"),
        ({"height": 2.5}, "height"),
        ({"cell_size": 0.0}, "cell_size"),
    ],
)
def test_bad_options(tmp_path, kw, match):
    with pytest.raises(InputError, match=match):
        make_synthetic_scene(tmp_path / "s", **kw)
    assert not (tmp_path / "s").exists()


# ------------------------------------------------------------------ CLI


def test_cli_demo(tmp_path, capsys):
    from o3d_seqcc.cli import main

    args = ["demo", "--out", str(tmp_path / "demo"), "--views", "4", "--width", "80", "--height", "60", "--cell-size", "0.15",
            "--t-npm", "50"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "v03" in out and "mean |diff|" in out
    summ = json.loads((tmp_path / "demo" / "demo_summary.json").read_text())
    assert summ["summary"]["load"]["views"] == 4
    assert summ["summary"]["synthetic"]["reused"] is False
    assert main(args) == 0  # same parameters: the scene is reused
    summ = json.loads((tmp_path / "demo" / "demo_summary.json").read_text())
    assert summ["summary"]["synthetic"]["reused"] is True
    assert main(args[:4] + ["3"] + args[5:]) == 2  # other parameters without --overwrite
    assert main(args[:4] + ["3"] + args[5:] + ["--overwrite"]) == 0


def test_cli_synthetic(tmp_path):
    from o3d_seqcc.cli import main

    out = tmp_path / "s"
    base = ["synthetic", str(out), "--views", "2", "--width", "48", "--height", "32", "--cell-size", "0.3"]
    assert main(base + ["--photometric", "none", "--seed", "4"]) == 0
    s = load_synthetic(out)
    assert s.metadata["photometric"] == "none" and s.metadata["seed"] == 4
    assert main(base) == 2
    assert main(base + ["--overwrite"]) == 0
    assert read_depth(out / "depth" / "v00.png", 1000.0).max() > 0.5
    assert read_image(out / "gt" / "v01.png").shape == (32, 48, 3)
