"""load_textured_mesh on meshes with several textures: our pages (OBJ, GLB) and texrecon-style OBJs.

trimesh's own merge packs several images into one with UVs scaled by (size - 1) / atlas, which
moves every lookup by up to a texel; the loader stacks the images instead and must give back
every face's colours exactly.
"""

from __future__ import annotations

import numpy as np
import pytest

from o3d_seqcc.texturing import TexturedMesh, load_textured_mesh
from o3d_seqcc.texturing.textured_mesh import sample_texture


def _soup(rng, n_faces: int, size: int, page: int, pages: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random triangles on a plane, UVs inside page ``page`` of ``pages`` stacked size x size pages."""
    xy = rng.uniform(3, size - 3, (n_faces, 3, 2))  # texel coordinates inside the page
    verts = np.concatenate([rng.uniform(0, 1, (n_faces, 3, 2)), np.zeros((n_faces, 3, 1))], axis=2).reshape(-1, 3)
    verts[:, 2] = page  # one plane per page: faces stay distinguishable by position
    uv = np.stack([xy[..., 0] / size, 1.0 - (page * size + xy[..., 1]) / (pages * size)], axis=-1).reshape(-1, 2)
    return verts, np.arange(3 * n_faces).reshape(-1, 3), uv


def _centroid_colours(tm: TexturedMesh) -> tuple[np.ndarray, np.ndarray]:
    """(F, 3) centroid positions sorted, and the texture colour at each face's UV centroid, same order."""
    pos = tm.vertices[tm.faces].mean(axis=1)
    col = sample_texture(tm.texture, tm.uv[tm.faces].mean(axis=1))
    order = np.lexsort(pos.T)
    return pos[order], col[order]


@pytest.mark.parametrize("fmt", ["obj", "glb"])
def test_our_pages_read_back_texel_for_texel(tmp_path, fmt):
    from o3d_seqcc.io.export import export_glb, export_obj

    rng = np.random.default_rng(3)
    S, P = 64, 3
    parts = [_soup(rng, 40, S, p, P) for p in range(P)]
    v = np.concatenate([a for a, _, _ in parts])
    f = np.concatenate([b + 120 * k for k, (_, b, _) in enumerate(parts)])
    uv = np.concatenate([c for _, _, c in parts])
    tex = rng.integers(0, 256, (P * S, S, 3), dtype=np.uint8)
    tm = TexturedMesh(vertices=v, faces=f, uv=uv, texture=tex, pages=P)
    path = (export_obj if fmt == "obj" else export_glb)(tm, tmp_path / f"mesh.{fmt}")
    back = load_textured_mesh(path)
    assert back.pages == P and back.texture.shape == tex.shape
    p0, c0 = _centroid_colours(tm)
    p1, c1 = _centroid_colours(back)
    np.testing.assert_allclose(p1, p0, atol=1e-6)
    # the files hold float32 UVs: 2e-4 is 1/20 of an 8-bit level; trimesh's packing is off by ~0.1
    np.testing.assert_allclose(c1, c0, atol=2e-4)
    assert sorted(map(bytes, back.page_textures())) == sorted(map(bytes, tm.page_textures()))


def test_texrecon_style_obj_pages_of_several_sizes(tmp_path):
    """texrecon writes one material per atlas page, pages of different sizes (2048, 512, 256 ...)."""
    from PIL import Image

    rng = np.random.default_rng(4)
    sizes = [64, 16, 32]
    lines, mtl, expect = ["mtllib t.mtl"], [], []
    base = 1
    for k, S in enumerate(sizes):
        img = rng.integers(0, 256, (S, S, 3), dtype=np.uint8)
        Image.fromarray(img).save(tmp_path / f"t_material{k:04d}_map_Kd.png")
        mtl += [f"newmtl material{k:04d}", f"map_Kd t_material{k:04d}_map_Kd.png"]
        v, f, uv = _soup(rng, 10, S, 0, 1)
        v[:, 2] = k
        lines += [f"v {a} {b} {c}" for a, b, c in v] + [f"vt {a} {b}" for a, b in uv]
        lines += [f"usemtl material{k:04d}"]
        lines += [f"f {a + base}/{a + base} {b + base}/{b + base} {c + base}/{c + base}" for a, b, c in f]
        base += len(v)
        expect.append((v[f].mean(axis=1), sample_texture(img, uv[f].mean(axis=1))))
    (tmp_path / "t.mtl").write_text("\n".join(mtl) + "\n")
    (tmp_path / "t.obj").write_text("\n".join(lines) + "\n")
    back = load_textured_mesh(tmp_path / "t.obj")
    assert back.texture.shape == (sum(sizes), max(sizes), 3) and back.pages == 1
    pos = np.concatenate([p for p, _ in expect])
    col = np.concatenate([c for _, c in expect])
    order = np.lexsort(pos.T)
    p1, c1 = _centroid_colours(back)
    np.testing.assert_allclose(p1, pos[order], atol=1e-6)
    np.testing.assert_allclose(c1, col[order], atol=1e-6)
