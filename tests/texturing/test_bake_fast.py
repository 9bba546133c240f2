"""The bake's fast paths give what the plain computations give (issue 21: the same bytes with less).

Each test states a known answer computed the direct way: texel centres tested against every
triangle, the whole-canvas distance transform, OpenCV's Lanczos at every point, xatlas packing
on the page itself, one thread instead of two, the sampling instead of the direct pixel read.
"""

from __future__ import annotations

import numpy as np
import pytest

from o3d_seqcc.texturing import atlas, bake, fill, packing, packing_child
from o3d_seqcc.texturing.bake import (barycentric, edge_texels, gutter_owner, gutter_texels, rasterize_faces,
                                      rasterize_owner, sample_image)

from test_texturing import CAMS, grid_mesh, project, restrict, smooth_images


def random_triangles(rng, n: int, size: int, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """``n`` random triangles of about ``scale`` texels on a ``size`` canvas, corners on a 1/256 grid."""
    base = rng.random((n, 2)) * size
    txy = np.repeat(base, 3, axis=0) + rng.normal(size=(3 * n, 2)) * scale
    return np.round(txy * 256) / 256, rng.permutation(3 * n).reshape(-1, 3)


def brute_owner(txy, faces, order, h, w):
    """The face drawn last among those whose triangle holds each texel centre (barycentric >= -1e-7)."""
    yy, xx = np.mgrid[0:h, 0:w]
    x, y = xx.ravel().astype(float), yy.ravel().astype(float)
    owner = np.full(h * w, -1)
    for f in order:  # drawing order: later faces overwrite
        p = txy[faces[f]]
        d = (p[1, 0] - p[0, 0]) * (p[2, 1] - p[0, 1]) - (p[2, 0] - p[0, 0]) * (p[1, 1] - p[0, 1])
        if abs(d) <= 1e-12:
            continue
        b = barycentric(txy, faces, np.full(len(x), f), x, y)
        owner[(b >= -1e-7).all(axis=1)] = f
    return owner


def test_rasterize_owner_is_the_last_face_holding_each_texel_centre(rng):
    txy, faces = random_triangles(rng, 60, 40, 4.0)
    order = rng.permutation(len(faces))
    owner = rasterize_owner(txy, faces, 42, 45, order=order, chunk=50)
    want = brute_owner(txy, faces, order, 42, 45)
    # a texel centre within 1e-7 of an edge may fall either way between the two tests: they are rare
    assert (owner == want).mean() > 0.995
    assert (owner >= 0).sum() > 500
    idx, face, bary = rasterize_faces(txy, faces, 42, 45, order=order, chunk=50)
    assert np.array_equal(idx, np.flatnonzero(owner >= 0)) and np.array_equal(face, owner[idx])
    y, x = np.divmod(idx, 45)
    assert np.allclose(bary, barycentric(txy, faces, face, x.astype(float), y.astype(float)), atol=1e-5)


def test_edge_texels_from_a_free_canvas_equal_those_from_the_covered_list(rng):
    txy, faces = random_triangles(rng, 300, 120, 3.0)
    owner = rasterize_owner(txy, faces, 128, 128)
    covered = np.flatnonzero(owner >= 0)
    a = edge_texels(txy, faces, covered, 128, 128)
    b = edge_texels(txy, faces, None, 128, 128, free=owner == -1)
    assert len(a[0]) > 0 and all(np.array_equal(u, v) for u, v in zip(a, b))



def test_edge_texels_in_runs_of_samples_equal_one_run(rng, monkeypatch):
    """Thin faces' edges sampled in many short runs give the texels and faces of a single run (first face wins)."""
    p = rng.random((400, 2)) * 120
    d = rng.normal(size=(400, 2)) * 8  # slivers: a long edge and a third corner near it
    txy = np.concatenate([p, p + d, p + 0.5 * d + rng.normal(size=(400, 2)) * 0.2]).round(4)
    faces = np.arange(1200).reshape(3, 400).T.copy()
    owner = rasterize_owner(txy, faces, 128, 128)
    one = edge_texels(txy, faces, None, 128, 128, free=owner == -1)
    monkeypatch.setattr(bake, "EDGE_SAMPLES", 37)  # runs that cut edges' samples anywhere
    many = edge_texels(txy, faces, None, 128, 128, free=owner == -1)
    assert len(one[0]) > 500 and len(np.unique(one[1])) > 100
    assert np.array_equal(one[0], many[0]) and np.array_equal(one[1], many[1])

@pytest.mark.parametrize("threads", [1, 2])
def test_gutters_in_bands_equal_the_whole_canvas_distance_transform(rng, monkeypatch, threads):
    monkeypatch.setattr(bake, "GUTTER_BAND_ROWS", 24)  # many bands on a small canvas
    txy, faces = random_triangles(rng, 250, 200, 6.0)
    H, W = 210, 190
    owner = rasterize_owner(txy, faces, H, W)
    eidx, eface = edge_texels(txy, faces, None, H, W, free=owner == -1)
    owner[eidx] = -2 - eface.astype(np.int32)  # texels given to a face outside it: covered too
    cov = np.flatnonzero(owner != -1)
    face = np.where(owner[cov] >= 0, owner[cov], -2 - owner[cov])
    want = gutter_texels(cov, face, H, W, reach=5.0)
    got = gutter_owner(owner, H, W, 5.0, threads=threads)
    assert len(want[0]) > 1000
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])


def test_sample_image_reads_pixel_centres_directly_as_the_lanczos_would(rng):
    img = rng.integers(0, 256, size=(37, 53, 3), dtype=np.uint8)
    n = 4000
    xi, yi = rng.integers(-4, 57, n), rng.integers(-4, 41, n)  # some outside the image: the border repeats
    jitter = rng.choice([0.0, 1e-4, -3e-3, 1 / 80, 0.02, 0.5], size=(n, 2))  # within and beyond 1/64 px
    x = (xi + jitter[:, 0]).astype(np.float32)
    y = (yi + jitter[:, 1]).astype(np.float32)
    got = sample_image(img, x, y, density=1.0)
    want = bake._sample_lanczos(img, x, y)  # OpenCV's Lanczos and the 2 x 2 clamp at every point
    assert np.array_equal(got, want)
    centre = (np.abs(jitter) < 1 / 64).all(axis=1)
    assert centre.sum() > n // 3
    assert np.array_equal(got[centre], img[np.clip(yi, 0, 36), np.clip(xi, 0, 52)][centre].astype(np.float32))


def _charts(rng, n: int):
    """``n`` small rectangular charts (two triangles each) with UVs in source pixels."""
    sx, sy = rng.uniform(3, 40, size=(2, n))
    lo = rng.uniform(0, 500, size=(n, 2))
    zero = np.zeros(n)
    corners = np.stack([lo, lo + np.stack([sx, zero], 1), lo + np.stack([sx, sy], 1), lo + np.stack([zero, sy], 1)], 1)
    uv = np.round(corners.reshape(-1, 2) * 256) / 256
    q = np.arange(n)[:, None] * 4
    faces = np.concatenate([q + [0, 1, 2], q + [0, 2, 3]])
    chart = np.concatenate([np.arange(n), np.arange(n)])
    return uv, faces, chart


def test_packing_once_is_packing_on_the_page(rng, monkeypatch):
    uv, faces, chart = _charts(rng, 300)
    fast = packing.pack_charts(uv, faces, chart, power_of_two=True)
    monkeypatch.setattr(packing._Packer, "unlimited", lambda self, t: None)  # the two xatlas calls of before
    slow = packing.pack_charts(uv, faces, chart, power_of_two=True)
    assert np.array_equal(fast.txy, slow.txy) and np.array_equal(fast.page, slow.page)
    assert (fast.size, fast.pages, fast.utilization, fast.log) == (slow.size, slow.pages, slow.utilization, slow.log)


def test_a_page_cut_to_the_charts_is_their_unlimited_placement(rng, monkeypatch):
    """The default page (cut to the charts) is xatlas's placement without a size limit: read off a power-of-two
    page (one xatlas call) it is the one xatlas's own unlimited packing gives (resolution 0), up to the rounding
    of a chart's whole-texel offset where that packing's float32 coordinates (over a side that is not a power of
    two) land on a half texel; the same page."""
    uv, faces, chart = _charts(rng, 300)
    fast = packing.pack_charts(uv, faces, chart)
    monkeypatch.setattr(packing._Packer, "unlimited", lambda self, t: None)
    slow = packing.pack_charts(uv, faces, chart)
    assert (fast.width, fast.height, fast.pages, fast.log) == (slow.width, slow.height, slow.pages, slow.log)
    d = np.abs(fast.txy - slow.txy)
    assert np.array_equal(d, np.rint(d)) and d.max() <= 1.0 and np.mean(d > 0) < 0.05


def test_a_packing_read_on_a_smaller_page_is_xatlas_own_on_that_page(rng):
    uv, faces, chart = _charts(rng, 200)
    pk = packing._Packer(uv, faces, chart, 4)
    free = pk.unlimited(1.0)
    assert free is not None
    big, W, H, R = free
    tight = pk.pack(1.0, 0)
    assert (W, H) == (tight.width, tight.height)  # the extents of the packing without a limit
    S = 1 << int(np.ceil(np.log2(max(W, H) + 1 + pk.largest_chart(1.0))))
    own, read = pk.pack(1.0, S), packing._OnPage(big, R, S)
    assert np.array_equal(own[0][2], read[0][2]) and np.array_equal(own[0][1], read[0][1])
    assert own.get_utilization(0) == read.get_utilization(0)


def test_the_unlimited_placement_is_read_off_the_smallest_page_that_holds_it(rng):
    uv, faces, chart = _charts(rng, 200)
    pk = packing._Packer(uv, faces, chart, 4)
    big, W, H, R = pk.unlimited(1.0)
    assert R < 2**15 and max(W, H) + 1 + pk.largest_chart(1.0) <= R
    smallest = 1 << int(np.ceil(np.log2(max(W, H) + 1 + pk.largest_chart(1.0))))
    assert R <= 2 * smallest  # the first page tried is near the smallest that holds it, not the largest
    largest = pk.pack(1.0, 2**15)  # what the first version read it off: the largest page
    uv_here, uv_there = big[0][2].astype(np.float64) * R, largest[0][2].astype(np.float64) * 2**15
    assert np.array_equal(uv_here, uv_there) and np.array_equal(big[0][1], largest[0][1])
    # a first page too small for it: packed again on pages twice as large until one holds it, the same placement
    again, W2, H2, R2 = pk.unlimited(1.0, start=16)
    assert (W2, H2, R2) == (W, H, R)
    assert np.array_equal(again[0][2].astype(np.float64) * R2, uv_here)


def test_packing_in_a_child_process_is_the_same_packing(rng, monkeypatch):
    uv, faces, chart = _charts(rng, 120)
    monkeypatch.setattr(packing_child, "BESIDE_MIN_FACES", 0)
    beside = packing_child.pack_charts_beside(uv, faces, chart, beside=True).result()
    here = packing.pack_charts(uv, faces, chart)
    assert np.array_equal(beside.txy, here.txy) and beside.log == here.log and beside.size == here.size


def test_the_packing_child_imports_what_this_process_imports(rng, monkeypatch, tmp_path, caplog):
    import logging
    import sys

    import xatlas  # noqa: F401 - this process's, imported before the working folder changes

    (tmp_path / "xatlas.py").write_text('raise SystemExit("the working folder\'s xatlas")\n')
    monkeypatch.chdir(tmp_path)  # a child started with -c would put this folder first on its path
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path))])
    monkeypatch.setattr(packing_child, "BESIDE_MIN_FACES", 0)
    uv, faces, chart = _charts(rng, 60)
    with caplog.at_level(logging.DEBUG, logger="o3d_seqcc.texturing.packing"):
        beside = packing_child.pack_charts_beside(uv, faces, chart, beside=True).result()
    assert not [r for r in caplog.records if "child failed" in r.getMessage()]  # packed in the child, not inline
    here = packing.pack_charts(uv, faces, chart)
    assert np.array_equal(beside.txy, here.txy) and beside.log == here.log


def _big_and_small_charts(rng):
    """A chart as large as a page's slack (600 x 500 px) among 150 small ones: packed twice (unlimited, then on the
    page)."""
    uv, faces, chart = _charts(rng, 150)
    big = np.array([[0.0, 0.0], [600.0, 0.0], [600.0, 500.0], [0.0, 500.0]]) + 1000.0
    n = len(uv)
    return (np.concatenate([uv, big]), np.concatenate([faces, [[n, n + 1, n + 2], [n, n + 2, n + 3]]]),
            np.concatenate([chart, [150, 150]]))


@pytest.mark.parametrize("guess", [packing_child._EXTENT_RATIO_GUESS, 0.3])  # the page the charts call for; a smaller one
def test_a_page_packed_beside_the_unlimited_one_is_the_same_packing(rng, monkeypatch, guess):
    uv, faces, chart = _big_and_small_charts(rng)
    here = packing.pack_charts(uv, faces, chart, power_of_two=True)
    assert len(here.log) == 2 and "without a size limit" in here.log[0]  # two xatlas calls: unlimited, on the page
    right = guess == packing_child._EXTENT_RATIO_GUESS
    monkeypatch.setattr(packing_child, "_EXTENT_RATIO_GUESS", guess)
    started = []
    speculate = packing_child.speculative_page
    monkeypatch.setattr(packing_child, "speculative_page", lambda *a: started.append(speculate(*a)) or started[-1])
    beside = packing_child.pack_speculating(uv, faces, chart, atlas_size="auto", texels_per_pixel="auto",
                                            overflow="scale", padding=4, power_of_two=True)
    assert started and started[0] is not None  # a child packed a page from the start
    assert (started[0].size == here.size) == right  # a wrong guess: its page is not the one used
    assert np.array_equal(beside.txy, here.txy) and np.array_equal(beside.page, here.page)
    assert (beside.size, beside.log, beside.utilization) == (here.size, here.log, here.utilization)


def test_pixel_aligned_faces_are_whole_offsets_of_their_photo_corners(rng):
    n = 50
    P = np.round(rng.uniform(0, 300, size=(5 * n, 3, 2)) * 256) / 256
    o = rng.integers(-40, 3000, size=(5 * n, 1, 2)).astype(float)
    T = P + o  # moved by whole texels
    T[n:2 * n] = P[n:2 * n, :, ::-1] + o[n:2 * n]  # turned by xatlas: x and y swapped
    T[2 * n:3 * n] += 0.5  # half a texel off: resampled
    T[3 * n:4 * n] = 1.001 * P[3 * n:4 * n] + o[3 * n:4 * n]  # another density
    P[4 * n:, 2] = P[4 * n:, 1]  # degenerate
    T[4 * n:] = P[4 * n:] + o[4 * n:]
    faces = np.arange(15 * n).reshape(-1, 3)
    ok, ox, oy, swap, limit = atlas._pixel_aligned(T.reshape(-1, 2), faces, P, 1.0)
    assert ok[:2 * n].all() and not ok[2 * n:].any()
    assert np.array_equal(ox[:n], o[:n, 0, 0]) and np.array_equal(oy[:n], o[:n, 0, 1]) and not swap[:n].any()
    assert np.array_equal(ox[n:2 * n], o[n:2 * n, 0, 0]) and swap[n:2 * n].all()
    assert (limit > 0).all() and not atlas._pixel_aligned(T.reshape(-1, 2), faces, P, 0.5)[0].any()


_PIXEL_ALIGNED = atlas._pixel_aligned


def _baked(monkeypatch, *, threads: int, aligned: bool, seed: int = 5):
    rng = np.random.default_rng(seed)
    mesh = grid_mesh(14)
    vis = project(mesh, CAMS)
    vis = restrict(vis, vis.usable & (rng.random(vis.usable.shape) > 0.3))
    # a coherent selection: the view of the face's quarter of the plane where usable, else another usable one
    cx = mesh.vertices[mesh.faces].mean(axis=1)[:, 0]
    want = np.clip(((cx + 1) * 2).astype(int), 0, 3)
    usable = vis.usable
    labels = np.where(usable[want, np.arange(len(want))], want, np.argmax(usable, axis=0))
    labels[~usable.any(axis=0)] = -1
    labels[:6] = -1  # some unseen faces: fallback colours in the same pass
    images = smooth_images(rng, CAMS, cell=2)
    monkeypatch.setattr(atlas, "_threads", lambda: threads)
    monkeypatch.setattr(atlas, "_BAND_TEXELS", 4096)  # many bands
    found = []
    real = _PIXEL_ALIGNED

    def spy(*args):
        out = real(*args) if aligned else (np.zeros(len(args[1]), bool),) + (None,) * 4
        found.append(int(out[0].sum()))
        return out

    monkeypatch.setattr(atlas, "_pixel_aligned", spy)
    return atlas.bake_texture(mesh, images, vis, labels), found[0]


def test_the_bake_in_bands_on_threads_with_direct_pixel_reads_equals_the_plain_one(monkeypatch):
    plain, none = _baked(monkeypatch, threads=1, aligned=False)
    fast, direct = _baked(monkeypatch, threads=2, aligned=True)
    assert none == 0 and direct > 0.9 * (fast.face_view >= 0).sum()  # nearly every seen face read directly
    assert np.array_equal(plain.texture, fast.texture) and np.array_equal(plain.uv, fast.uv)
    assert plain.stats["unseen_faces"] > 0 and plain.stats["texels_per_pixel"] == 1.0


def test_the_childs_warnings_and_log_records_reach_this_process_as_its_own(rng, monkeypatch, caplog):
    import logging
    import warnings

    from o3d_seqcc.errors import O3dSeqccWarning

    uv, faces, chart = _charts(rng, 120)
    monkeypatch.setattr(packing_child, "BESIDE_MIN_FACES", 0)
    with caplog.at_level(logging.WARNING, logger=packing.logger.name), warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        res = packing_child.pack_charts_beside(uv, faces, chart, beside=True, atlas_size=256).result()  # too small: scaled
    assert res.scale < 1
    assert any(issubclass(x.category, O3dSeqccWarning) and "density scaled" in str(x.message) for x in w)
    levels = {r.levelname for r in caplog.records if r.name == packing.logger.name}
    assert "WARNING" in levels and "INFO" not in levels  # the INFO line is below this process's level
    with pytest.raises(packing.InputError, match="could not pack"):
        packing_child.pack_charts_beside(uv, faces, chart, beside=True, atlas_size=8, padding=8).result()


def test_the_face_canvas_and_the_fill_in_bands_on_threads_are_the_single_pass_ones(rng, monkeypatch):
    monkeypatch.setattr(bake, "RASTER_BAND_ROWS", 16)
    monkeypatch.setattr(fill, "FILL_BAND_ROWS", 32)
    txy, faces = random_triangles(rng, 400, 150, 5.0)
    order = rng.permutation(len(faces))
    one = rasterize_owner(txy, faces, 160, 150, order=order)
    two = rasterize_owner(txy, faces, 160, 150, order=order, threads=2)
    assert np.array_equal(one, two) and (one >= 0).sum() > 3000
    img = rng.integers(0, 256, size=(160, 150, 3), dtype=np.uint8)
    mask = one.reshape(160, 150) >= 0
    a = fill.push_pull_fill(img, mask)
    b = fill.push_pull_fill(img.copy(), mask, copy=False, threads=2)
    assert np.array_equal(a, b) and not np.array_equal(a, img)
