"""The visibility's fast paths (split bookkeeping, culling, rays) give what the former computations gave, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from _mapping_scenes import box, look_at, make_scene, merge, plane
from o3d_seqcc import InputError
from o3d_seqcc.geometry.meshops import weld_vertices
from o3d_seqcc.geometry.meshsplit import bisect, coarsen
from o3d_seqcc.visibility import refine
from o3d_seqcc.visibility.compute import compute_visibility
from o3d_seqcc.visibility.per_view import DEPTH, MASKED, OBLIQUE, OCCLUDED, ViewRecord


def _reference_coarsen(faces, welded, ends, unseen):
    """The coarsening with every midpoint looked at in every pass."""
    w = np.asarray(welded)
    cur = np.asarray(faces, dtype=np.int64).copy()
    origin = np.arange(len(cur), dtype=np.int64)
    rep, pos, dark = origin.copy(), origin.astype(np.float64), np.asarray(unseen, dtype=bool).copy()
    is_mid = ends[:, 0] >= 0
    nm, span = len(w), int(w.max()) + 1
    while True:
        fi, j = np.nonzero(is_mid[cur])
        if not len(fi):
            break
        m = cur[fi, j]
        o1, o2 = cur[fi, (j + 1) % 3], cur[fi, (j + 2) % 3]
        wp, wq = w[ends[m, 0]], w[ends[m, 1]]
        e1, e2 = (w[o1] == wp) | (w[o1] == wq), (w[o2] == wp) | (w[o2] == wq)
        follow, precede = e1 & ~e2, e2 & ~e1
        ok = dark[fi] & (follow ^ precede)
        apex, end = np.where(follow, o2, o1), np.where(follow, o1, o2)
        uk, g = np.unique(m * span + w[apex], return_inverse=True)
        good_g = ((np.bincount(g, weights=precede & ok, minlength=len(uk)) == 1)
                  & (np.bincount(g, weights=follow & ok, minlength=len(uk)) == 1) & (np.bincount(g) == 2))
        bad_m = np.bincount(m, weights=~good_g[g], minlength=nm) > 0
        n_groups = np.bincount(uk // span, minlength=nm)
        cand_pair = (~bad_m & (n_groups >= 1) & (n_groups <= 2))[m]
        if not cand_pair.any():
            break
        owner = np.full(len(cur), -1, dtype=np.int64)
        np.maximum.at(owner, fi[cand_pair], m[cand_pair])
        lost = np.bincount(m[cand_pair], weights=owner[fi[cand_pair]] != m[cand_pair], minlength=nm) > 0
        take = cand_pair & ~lost[m]
        if not take.any():
            break
        gi = g[take]
        order = np.argsort(gi, kind="stable")
        fi_t, gi_t = fi[take][order], gi[order]
        pre_t, end_t, apex_t = precede[take][order], end[take][order], apex[take][order]
        first = np.flatnonzero(np.r_[True, gi_t[1:] != gi_t[:-1]])
        a_idx, b_idx = np.where(pre_t[first], first, first + 1), np.where(pre_t[first], first + 1, first)
        merged = np.stack([end_t[a_idx], end_t[b_idx], apex_t[first]], axis=1)
        halves = np.stack([fi_t[a_idx], fi_t[b_idx]], axis=1)
        alive = np.ones(len(cur), dtype=bool)
        alive[halves.reshape(-1)] = False
        cur = np.concatenate([cur[alive], merged])
        origin = np.concatenate([origin[alive], np.full(len(merged), -1, dtype=np.int64)])
        rep = np.concatenate([rep[alive], rep[halves[:, 0]]])
        pos = np.concatenate([pos[alive], pos[halves].min(axis=1)])
        dark = np.concatenate([dark[alive], np.ones(len(merged), dtype=bool)])
    order = np.argsort(pos, kind="stable")
    return cur[order], origin[order], rep[order]


def _split_rounds(rng, rounds: int):
    """A plane split the way refine_visibility splits (two bisections a round), with its midpoints' ends."""
    X, f = plane(6, size=2.0)
    welded = weld_vertices(X)
    ends = np.full((len(X), 2), -1, dtype=np.int64)
    for _ in range(rounds):
        marked = np.flatnonzero(rng.random(len(f)) < 0.4)
        b1 = bisect(X, f, marked, welded=welded)
        w1 = np.concatenate([welded, welded.max() + 1 + np.arange(b1.n_new_vertices)])
        b2 = bisect(b1.vertices, b1.faces, np.flatnonzero(np.isin(b1.parent, marked)), welded=w1)
        welded = np.concatenate([w1, w1.max() + 1 + np.arange(b2.n_new_vertices)])
        ends = np.concatenate([ends, b1.edge_vertices, b2.edge_vertices])
        X, f = b2.vertices, b2.faces
    return X, f, welded, ends


@pytest.mark.parametrize("seed", range(4))
def test_coarsen_equals_the_pass_over_every_midpoint(seed):
    """Unseen regions (a half-plane, plus random faces) merged back: the same faces, origins and representatives as
    when every midpoint is looked at again in every pass, and merges did happen over several passes."""
    rng = np.random.default_rng(seed)
    X, f, welded, ends = _split_rounds(rng, 4)
    cen = X[f].mean(axis=1)
    unseen = (cen[:, 0] < rng.uniform(-0.5, 0.5)) | (rng.random(len(f)) < 0.2)
    got = coarsen(f, welded, ends, unseen)
    ref = _reference_coarsen(f, welded, ends, unseen)
    for a, b in zip(got, ref):
        np.testing.assert_array_equal(a, b)
    assert len(got[0]) < len(f) - 20


def _reference_best_view(records, among):
    """The largest usable area per face, the first view on a tie (a lexsort of every incidence)."""
    vv, ff, aa = [], [], []
    for v, r in enumerate(records):
        k = (r.flags == 0) & among[r.faces]
        vv.append(np.full(int(k.sum()), v))
        ff.append(r.faces[k].astype(np.int64))
        aa.append(r.area[k])
    vv, ff, aa = np.concatenate(vv), np.concatenate(ff), np.concatenate(aa)
    order = np.lexsort((-aa, ff))
    first = np.r_[True, ff[order][1:] != ff[order][:-1]]
    return ff[order][first], vv[order][first]


def test_distortion_takes_the_largest_view_first_on_ties(monkeypatch, rng):
    """Random records with areas drawn from a few values (many ties): distortion measures every face in the view the
    lexsort of all incidences picks."""
    F, V = 300, 6
    records = []
    for _ in range(V):
        faces = np.sort(rng.choice(F, size=200, replace=False)).astype(np.int32)
        records.append(ViewRecord(faces=faces, flags=(rng.random(200) < 0.3).astype(np.uint8),
                                  area=rng.choice([0.0, 1.5, 2.0, 7.25], size=200).astype(np.float32),
                                  cos_angle=np.ones(200, np.float32)))
    among = rng.random(F) < 0.8
    seen = {}

    def project(XT, K, E):
        seen[int(K[0, 0])] = XT
        return np.zeros(XT.shape[1]), np.zeros(XT.shape[1]), np.ones(XT.shape[1])

    monkeypatch.setattr(refine, "project_columns", project)

    class _View:
        def __init__(self, v):
            self.intrinsic, self.extrinsic = np.diag([v + 1.0, 1.0, 1.0]), np.eye(4)

    X = rng.normal(size=(F * 3, 3))
    faces = np.arange(F * 3).reshape(F, 3)
    refine.distortion(X, faces, records, [_View(v) for v in range(V)], among)
    ff, vv = _reference_best_view(records, among)
    for v in range(V):  # each view projected exactly its faces' corners and points, in ascending face order
        fs = ff[vv == v]
        if len(fs):
            np.testing.assert_array_equal(seen[v + 1][:, ::7].T, X[faces[fs, 0]])
        else:
            assert v + 1 not in seen


def _merge(old, new, old_to_new, new_ids):
    """One round's merge of a view's record (what every round did before the records were renumbered once)."""
    keep = old_to_new[old.faces] >= 0
    faces = np.concatenate([old_to_new[old.faces[keep]], new_ids[new.faces]])
    order = np.argsort(faces, kind="stable")
    flags = np.concatenate([old.flags[keep], new.flags])[order]
    info = dict(old.info)
    info.update(valid=int(len(faces)), occluded=int(np.count_nonzero(flags & OCCLUDED)),
                depth_inconsistent=int(np.count_nonzero(flags & DEPTH)),
                oblique=int(np.count_nonzero(flags & OBLIQUE)), masked=int(np.count_nonzero(flags & MASKED)),
                usable=int(np.count_nonzero(flags == 0)))
    return ViewRecord(faces=faces[order].astype(np.int32), flags=flags,
                      area=np.concatenate([old.area[keep], new.area])[order],
                      cos_angle=np.concatenate([old.cos_angle[keep], new.cos_angle])[order], info=info,
                      n_rays=old.n_rays + new.n_rays, n_known=old.n_known)


def _random_record(rng, n_faces: int, k: int) -> ViewRecord:
    faces = np.sort(rng.choice(n_faces, size=min(k, n_faces), replace=False)).astype(np.int32)
    m = len(faces)
    return ViewRecord(faces=faces, flags=rng.integers(0, 8, m).astype(np.uint8), area=rng.random(m).astype(np.float32),
                      cos_angle=rng.random(m).astype(np.float32), info={"name": "v", "depth_source": None, "valid": m},
                      n_rays=int(rng.integers(100)), n_known=int(rng.integers(100)))


def test_records_renumbered_once_equal_the_merge_of_every_round(rng):
    """Rounds of faces split (renumbered, their parts appended) and the parts' records added: the records built
    once at the end equal those merged round by round, and the usable-anywhere flags follow."""
    n, V = 400, 3
    merged = [_random_record(rng, n, 250) for _ in range(V)]
    book = refine._Records(merged, n)
    for _ in range(4):
        split = rng.random(n) < 0.2
        n_new = int(split.sum()) * 3
        old_to_new = np.full(n, -1, dtype=np.int64)  # unsplit faces keep their order, the parts go in between
        slots = np.sort(rng.choice(n - split.sum() + n_new, size=n - split.sum(), replace=False))
        old_to_new[~split] = slots
        n = n - int(split.sum()) + n_new
        new = np.setdiff1d(np.arange(n), slots)
        parts = [_random_record(rng, len(new), 60) for _ in range(V)]
        merged = [_merge(o, p, old_to_new, new) for o, p in zip(merged, parts)]
        book.renumber(old_to_new, n)
        book.add(parts, new)
        usable = np.zeros(n, dtype=bool)
        for r in merged:
            usable[r.faces[r.flags == 0]] = True
        np.testing.assert_array_equal(book.usable_any, usable)
    for a, b in zip(book.records(), merged):
        for name in ("faces", "flags", "area", "cos_angle"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
            assert getattr(a, name).dtype == getattr(b, name).dtype
        assert (a.info, a.n_rays, a.n_known) == (b.info, b.n_rays, b.n_known)


def test_probe_culling_keeps_the_split(tmp_path, monkeypatch):
    """A fine floor partly under a box, partly outside the photo: the probes culled by candidate chunks (chunks of 8)
    split the same faces into the same parts as probes over every candidate."""
    v, f = merge(plane(20, size=3.0), box((-0.2, -0.2, 0.0), (0.2, 0.2, 0.4)))
    cams = [look_at((0.3, -0.6, 1.0), (0.0, 0.0, 0.0)), look_at((-0.5, 0.4, 0.9), (0.2, 0.1, 0.0))]
    scene = make_scene(tmp_path, (v, f), cams)
    monkeypatch.setattr(refine, "PROBE_CHUNK", 10**9)
    whole = compute_visibility(scene)
    monkeypatch.setattr(refine, "PROBE_CHUNK", 8)
    looked = []
    candidates = refine.ProbeJob.candidates
    monkeypatch.setattr(refine.ProbeJob, "candidates", lambda self, view: looked.append(
        (len(self.tri), len(c) if (c := candidates(self, view)) is not None else len(self.tri))) or c)
    culled = compute_visibility(scene)
    assert any(n_in < n for n, n_in in looked)  # some candidates were culled
    assert whole.stats["split"]["faces_split"] > 10
    np.testing.assert_array_equal(whole.mesh.faces, culled.mesh.faces)
    np.testing.assert_array_equal(whole.mesh.vertices, culled.mesh.vertices)
    for a, b in zip(whole.records, culled.records):
        for name in ("faces", "flags", "area", "cos_angle"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_rays_are_the_float64_rays_rounded(rng):
    """Points at every scale around a camera far from the origin, some at the camera itself: the rays' bits equal
    those of the float64 rays (np.linalg.norm distances) rounded to float32 at the end."""
    from o3d_seqcc.visibility.occlusion import _rays_to

    C = rng.normal(size=3) * 1e6
    P = C + rng.normal(size=(20000, 3)) * 10.0 ** rng.uniform(-4, 3, size=(20000, 1))
    P[:30] = C
    origin = C + rng.normal(size=3)
    for tol, atol, o in ((1e-3, 1e-6, origin), (0.0, 0.0, None), (0.05, 2.0, origin)):
        d = P - C
        dist = np.linalg.norm(d, axis=1, keepdims=True)
        reach = np.maximum(dist * (1.0 - tol) - atol, 0.0)
        d = d * np.divide(reach, dist, out=np.zeros_like(dist), where=dist > 0)
        c = C if o is None else C - o
        ref = np.concatenate([np.broadcast_to(c, d.shape), d], axis=1).astype(np.float32)
        got = _rays_to(C, P, tol, atol, o)
        assert got.dtype == np.float32 and got.shape == ref.shape
        np.testing.assert_array_equal(got.view(np.uint32), ref.view(np.uint32))


def test_depth_maps_held_as_counts_look_up_what_load_depth_reads(tmp_path, rng):
    """A 16-bit PNG depth map is held as its counts (a quarter of the float image's bytes) and looks up the float64
    bits View.load_depth gives, down to the smallest depth scale a View takes (a scale that would put depths beyond
    MAX_COORDINATE, such as 1.03e-9, is refused when the View is made)."""
    from dataclasses import replace

    from o3d_seqcc.visibility.depthmaps import DepthImage
    from o3d_seqcc.visibility.per_view import _depth_image

    v, f = plane(4, size=1.0)
    scene = make_scene(tmp_path, (v, f), [look_at((0.1, 0.0, 1.0), (0.0, 0.0, 0.0))])
    from o3d_seqcc.io.mesh_files import MAX_COORDINATE
    from o3d_seqcc.scene import DEPTH_SCALE_RANGE

    assert np.iinfo(np.uint16).max / DEPTH_SCALE_RANGE[0] < MAX_COORDINATE  # no 16-bit depth reaches it
    with pytest.raises(InputError, match="depth_scale must be between"):
        replace(scene.views[0], depth_scale=1.03e-9)
    for scale in (1000.0, 7.3, DEPTH_SCALE_RANGE[0]):
        view = replace(scene.views[0], depth_scale=scale)
        img, source = _depth_image(view, {"fill_radius": 0})
        D = view.load_depth()
        assert source == "depth" and img.counts is not None and img.nbytes * 4 == D.nbytes
        r, c = rng.integers(0, D.shape[0], 3000), rng.integers(0, D.shape[1], 3000)
        np.testing.assert_array_equal(img.at(r, c).view(np.uint64), D[r, c].view(np.uint64))
        np.testing.assert_array_equal(img.image().view(np.uint64), D.view(np.uint64))
    assert (D > 0).any()
    held = DepthImage(D)
    assert held.counts is None and held.nbytes == D.nbytes
    np.testing.assert_array_equal(held.at(r, c), D[r, c])


def test_vertex_projections_are_the_projections_rows(tmp_path, monkeypatch, rng):
    """vertex_projection's one-dimensional take gives the rows of the view's projection (repeats, negative ids), cached
    or not; out-of-range ids still raise."""
    from o3d_seqcc.visibility import compute

    v, f = plane(6, size=1.0)
    scene = make_scene(tmp_path, (v, f), [look_at((0.1, 0.0, 1.0), (0.0, 0.0, 0.0)), look_at((0.4, 0.2, 0.8), (0, 0, 0))])
    vis = compute_visibility(scene, split_faces=False)
    n = len(vis.mesh.vertices)
    ids = rng.integers(-n, n, 500)
    for budget in (compute.CACHE_BYTES, 0):
        monkeypatch.setattr(compute, "CACHE_BYTES", budget)
        for view in range(vis.n_views):
            uv, z = vis._project(view, None)
            got_uv, got_z = vis.vertex_projection(view, ids)
            assert got_uv.dtype == np.float32 and got_uv.shape == (500, 2) and got_uv.flags.c_contiguous
            np.testing.assert_array_equal(got_uv.view(np.uint32), uv[ids].view(np.uint32))
            np.testing.assert_array_equal(got_z.view(np.uint32), z[ids].view(np.uint32))
    with pytest.raises(IndexError):
        vis.vertex_projection(0, [n])


def test_vertices_at_one_position_share_their_ray(tmp_path, monkeypatch):
    """A floor and a box stored with three vertices per face: one ray per position gives the records and the ray
    counts of one ray per vertex (fewer rays cast)."""
    from o3d_seqcc.visibility import occlusion, per_view

    v, f = merge(plane(10, size=1.6), box((-0.15, -0.15, 0.0), (0.15, 0.15, 0.3)))
    vu, fu = v[f.reshape(-1)], np.arange(f.size).reshape(-1, 3)
    cams = [look_at((0.4, -0.9, 1.6), (0.0, 0.0, 0.0)), look_at((-0.6, 0.5, 1.2), (0.1, 0.0, 0.0))]
    scene = make_scene(tmp_path, (vu, fu), cams, mesh_normals=False)
    cast = []
    hidden = occlusion._hidden
    monkeypatch.setattr(occlusion, "_hidden", lambda rs, rays: cast.append(len(rays)) or hidden(rs, rays))
    shared = compute_visibility(scene, split_faces=False)
    n_shared = sum(cast)
    cast.clear()
    monkeypatch.setattr(per_view, "same_positions", lambda X: None)
    each = compute_visibility(scene, split_faces=False)
    assert sum(cast) > n_shared
    assert shared.stats["rays"] == each.stats["rays"] == sum(cast)
    for a, b in zip(shared.records, each.records):
        for name in ("faces", "flags", "area", "cos_angle"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        assert a.info == b.info
    assert any((r.flags & 1).any() for r in shared.records)  # some faces hidden


def test_the_camera_checks_ray_casting_scene_is_handed_to_the_visibility(tmp_path, monkeypatch):
    """load_scene's camera check hands its ray-casting scene over: the visibility takes it (not built twice), and its
    records equal those of a scene built anew; other arrays never get it."""
    from o3d_seqcc import load_scene
    from o3d_seqcc.visibility import occlusion, per_view

    v, f = merge(plane(10, size=1.6), box((-0.15, -0.15, 0.0), (0.15, 0.15, 0.3)))
    make_scene(tmp_path, (v, f), [look_at((0.4, -0.9, 1.6), (0.0, 0.0, 0.0)), look_at((-0.6, 0.5, 1.2), (0, 0, 0))])
    scene = load_scene(tmp_path / "scene.json")
    mesh = scene.load_mesh()
    assert occlusion.take_over(mesh.vertices.copy(), mesh.faces, np.zeros(3)) is None
    taken = []
    take = per_view.take_over
    monkeypatch.setattr(per_view, "take_over", lambda *a: taken.append(take(*a)) or taken[-1])
    handed = compute_visibility(scene)
    assert len(taken) == 1 and taken[0] is not None and not occlusion._HANDED
    built = compute_visibility(scene)
    assert taken[1] is None
    for a, b in zip(handed.records, built.records):
        for name in ("faces", "flags", "area", "cos_angle"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
