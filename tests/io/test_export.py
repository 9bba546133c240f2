"""Tests of o3d_seqcc.io.export: OBJ+MTL+PNG, GLB (glTF 2.0, Khronos validator), PLY, MeshLab's textured PLY."""

from __future__ import annotations

import json

import numpy as np
import pytest

from o3d_seqcc.errors import InputError
from o3d_seqcc.io.gltf_validator import find_validator, validate_glb
from o3d_seqcc.io.export import (
    export_glb,
    export_meshlab_ply,
    export_obj,
    export_ply,
    export_textured_mesh,
    glb_bytes,
)
from o3d_seqcc.texturing import TexturedMesh

import pymeshlab
import trimesh


@pytest.fixture
def textured(rng) -> TexturedMesh:
    """Two charts (a quad split in two triangles, each its own chart) on a 16 x 16 atlas."""
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float64)
    f = np.array([[0, 1, 2], [3, 4, 5]], dtype=np.int64)
    S = 16
    tex = rng.integers(0, 256, size=(S, S, 3), dtype=np.uint8)
    texel = np.array([[1, 1], [6, 1], [6, 6], [9, 9], [14, 14], [9, 14]], dtype=np.float64)
    uv = np.stack([(texel[:, 0] + 0.5) / S, 1.0 - (texel[:, 1] + 0.5) / S], axis=1)  # OBJ convention, v up
    n = np.tile([0.0, 0.0, 1.0], (6, 1))
    return TexturedMesh(vertices=v, faces=f, uv=uv, normals=n, texture=tex, face_view=np.array([0, 1]),
                        vertex_index=np.array([0, 1, 2, 0, 2, 3]), face_chart=np.array([0, 1]), stats={})


def _texel_of_vertex(mesh, uv_obj: np.ndarray, k: int, tex: np.ndarray) -> np.ndarray:
    """Texture colour at vertex k given OBJ-convention uv (v up)."""
    S = tex.shape[0]
    x = int(round(uv_obj[k, 0] * S - 0.5))
    y = int(round((1.0 - uv_obj[k, 1]) * S - 0.5))
    return tex[y, x]


def _loaded_texture(m) -> np.ndarray:
    mat = m.visual.material
    img = getattr(mat, "baseColorTexture", None) or getattr(mat, "image", None)
    assert img is not None, "texture missing"
    return np.asarray(img.convert("RGB"))


@pytest.mark.parametrize("fmt", ["obj", "glb"])
def test_roundtrip_trimesh(tmp_path, textured, fmt):
    path = (export_obj if fmt == "obj" else export_glb)(textured, tmp_path / f"mesh.{fmt}")
    if fmt == "obj":
        assert (tmp_path / "mesh.mtl").is_file() and (tmp_path / "mesh.png").is_file()
        assert "map_Kd mesh.png" in (tmp_path / "mesh.mtl").read_text()
    m = trimesh.load(str(path), force="mesh", process=False)
    assert len(m.vertices) == len(textured.vertices) and len(m.faces) == len(textured.faces)
    np.testing.assert_allclose(m.vertices, textured.vertices, atol=1e-6)
    uv = np.asarray(m.visual.uv)
    assert uv.min() >= 0 and uv.max() <= 1
    tex = _loaded_texture(m)
    np.testing.assert_array_equal(tex, textured.texture)  # PNG is lossless
    # trimesh gives OBJ-convention UVs for both formats: the texel under every vertex must match
    for k in range(len(textured.vertices)):
        x, y = textured.texel_xy()[k].round().astype(int)
        np.testing.assert_array_equal(_texel_of_vertex(m, uv, k, tex), textured.texture[y, x])
    assert not list(tmp_path.glob(".*.tmp")), "temporary files left behind"


def test_obj_vt_convention(tmp_path, textured):
    export_obj(textured, tmp_path / "m.obj")
    vt = np.array([[float(x) for x in ln.split()[1:]] for ln in (tmp_path / "m.obj").read_text().splitlines()
                   if ln.startswith("vt ")])
    np.testing.assert_allclose(vt, textured.uv, atol=1e-6)  # our UVs are in the OBJ convention already


def _json_chunk(data: bytes) -> dict:
    jlen = int(np.frombuffer(data[12:16], dtype="<u4")[0])
    return json.loads(data[20:20 + jlen])


def test_glb_layout(textured):
    data = glb_bytes(textured)
    magic, version, length = np.frombuffer(data[:12], dtype="<u4")
    assert data[:4] == b"glTF" and version == 2 and length == len(data) and len(data) % 4 == 0
    jlen = int(np.frombuffer(data[12:16], dtype="<u4")[0])
    assert jlen % 4 == 0 and data[16:20] == b"JSON"
    gltf = json.loads(data[20:20 + jlen])
    assert all(bv["byteOffset"] % 4 == 0 for bv in gltf["bufferViews"])
    prim = gltf["meshes"][0]["primitives"][0]
    assert set(prim["attributes"]) == {"POSITION", "NORMAL", "TEXCOORD_0"}
    pbr = gltf["materials"][0]["pbrMetallicRoughness"]
    assert pbr["baseColorTexture"]["index"] == 0 and pbr["metallicFactor"] == 0
    assert gltf["images"][0]["mimeType"] == "image/png"
    # glTF UV origin is top-left: TEXCOORD_0 == (u, 1 - v) of our (OBJ-convention) uv
    acc = gltf["accessors"][prim["attributes"]["TEXCOORD_0"]]
    bv = gltf["bufferViews"][acc["bufferView"]]
    start = 20 + jlen + 8 + bv["byteOffset"]
    uv = np.frombuffer(data[start:start + bv["byteLength"]], dtype="<f4").reshape(-1, 2)
    np.testing.assert_allclose(uv, np.stack([textured.uv[:, 0], 1.0 - textured.uv[:, 1]], axis=1), atol=1e-7)
    unlit = _json_chunk(glb_bytes(textured, unlit=True))
    assert "KHR_materials_unlit" in unlit["extensionsUsed"]
    assert "KHR_materials_unlit" in unlit["materials"][0]["extensions"]


def _baked(rng) -> TexturedMesh:
    """A real bake: a 6 x 6 grid seen by two cameras, one face seen by none (fallback colour)."""
    from o3d_seqcc.visibility.compute import Visibility

    from o3d_seqcc.scene import Mesh
    from o3d_seqcc.texturing import bake_texture, select_views

    xs = np.linspace(-1, 1, 7)
    gx, gy = np.meshgrid(xs, xs)
    v = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], 1)
    a = (np.arange(6)[:, None] * 7 + np.arange(6)[None, :]).ravel()
    f = np.concatenate([np.stack([a, a + 1, a + 8], 1), np.stack([a, a + 8, a + 7], 1)])
    mesh = Mesh(vertices=v, faces=f, vertex_normals=np.tile([0.0, 0.0, -1.0], (len(v), 1)))
    uv, area = [], []
    for cx, d in ((0.0, 2.5), (0.3, 2.2)):
        p = (v[:, :2] - [cx, 0.0]) / d * 60.0 + [63.5, 47.5]
        e1, e2 = p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]]
        uv.append(p)
        area.append(0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]))
    usable = np.ones((2, len(f)), bool)
    usable[:, 0] = False
    vis = Visibility.from_arrays(mesh, np.array(uv), usable, area=np.array(area))
    images = [rng.integers(0, 256, size=(96, 128, 3), dtype=np.uint8) for _ in range(2)]
    return bake_texture(mesh, images, vis, select_views(vis, method="random"), atlas_size=128)


def test_glb_passes_khronos_validator(tmp_path, textured, rng):
    if find_validator() is None:
        pytest.skip("Node.js or the npm package gltf-validator is missing (./dev.sh setup installs both)")
    baked = _baked(rng)
    assert baked.stats["unseen_faces"] == 1
    for k, (tm, unlit) in enumerate(((textured, False), (textured, True), (baked, False))):
        issues = validate_glb(export_glb(tm, tmp_path / f"m{k}.glb", unlit=unlit))
        assert issues["numErrors"] == 0, issues["messages"]
        assert issues["numWarnings"] == 0, issues["messages"]


def test_ply_vertex_colours(tmp_path, textured):
    path = export_ply(textured, tmp_path / "m.ply")
    m = trimesh.load(str(path), process=False)
    assert len(m.vertices) == 6 and len(m.faces) == 2
    cols = np.asarray(m.visual.vertex_colors)[:, :3]
    for k in range(6):
        x, y = textured.texel_xy()[k].round().astype(int)
        np.testing.assert_array_equal(cols[k], textured.texture[y, x])


def test_textured_ply_reads_in_meshlab_with_our_uv(tmp_path, rng):
    """``export_meshlab_ply``: MeshLab reads our texture coordinates and texture, and colours each
    vertex from the texel we put under it (v up, as OBJ)."""
    S = 16
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 0, 1], [1, 1, 1], [0, 1, 1]], dtype=np.float64)
    f = np.array([[0, 1, 2], [3, 4, 5]], dtype=np.int64)
    texel = np.array([[1, 1], [6, 1], [6, 6], [9, 9], [14, 14], [9, 14]])
    uv = np.stack([(texel[:, 0] + 0.5) / S, 1.0 - (texel[:, 1] + 0.5) / S], axis=1)
    tex = rng.integers(0, 256, size=(S, S, 3), dtype=np.uint8)
    tm = TexturedMesh(vertices=v, faces=f, uv=uv, normals=np.tile([0.0, 0, 1], (6, 1)), texture=tex,
                      face_view=np.array([0, 1]), vertex_index=np.arange(6), face_chart=np.array([0, 1]), stats={})
    path = export_meshlab_ply(tm, tmp_path / "m.ply")
    assert (tmp_path / "m.png").is_file() and b"comment TextureFile m.png\n" in path.read_bytes()[:300]
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(path))
    m = ms.current_mesh()
    assert list(m.textures()) == ["m.png"] and m.has_wedge_tex_coord()
    np.testing.assert_allclose(m.wedge_tex_coord_matrix(), uv[f].reshape(-1, 2), atol=1e-6)
    ms.transfer_texture_to_color_per_vertex(sourcemesh=0, targetmesh=0)
    got = np.rint(ms.current_mesh().vertex_color_matrix()[:, :3] * 255)
    np.testing.assert_array_equal(got, tex[texel[:, 1], texel[:, 0]])
    with pytest.raises(InputError, match="does not exist"):
        export_meshlab_ply(tm, tmp_path / "n.ply", texture=tmp_path / "missing.png")


def test_export_textured_mesh_formats(tmp_path, textured):
    out = export_textured_mesh(textured, tmp_path, formats=["glb", "obj", "ply"])
    assert {k: p.name for k, p in out.items()} == {"glb": "mesh.glb", "obj": "mesh.obj", "ply": "mesh_colors.ply"}
    with pytest.raises(InputError, match="fbx"):
        export_textured_mesh(textured, tmp_path, formats=["fbx"])


def test_export_bad_input(tmp_path, textured):
    from dataclasses import replace

    with pytest.raises(InputError, match="texture"):
        export_glb(replace(textured, texture=textured.texture.astype(np.float32)), tmp_path / "x.glb")
    with pytest.raises(InputError, match="face indices"):
        export_obj(replace(textured, faces=textured.faces + 10), tmp_path / "x.obj")
    assert not (tmp_path / "x.glb").exists() and not (tmp_path / "x.obj").exists()


# ---- the OBJ's text formatted by numpy: Python's bytes ---------------------------------------------------------------


def _adversarial(rng) -> np.ndarray:
    """Random values over 60 decades, ties and near-ties of the digits written, powers of ten and their neighbours,
    zeros of both signs, subnormals, the largest float, NaN and infinities."""
    p = 10.0 ** np.arange(-30, 30)
    return np.concatenate([
        rng.normal(size=3000), rng.normal(size=3000) * 1e-3, 10.0 ** rng.uniform(-30, 30, 3000) * rng.choice([-1, 1], 3000),
        np.round(rng.uniform(-2, 2, 3000), 8) + 5e-9, np.round(rng.uniform(-2, 2, 3000), 6) - 5e-7, (np.arange(1000) + 0.5) / 2 ** 10,
        p, -p, np.nextafter(p, 0), np.nextafter(p, np.inf), 9.9999999995 * p[25:35],
        [0.0, -0.0, 1e-320, 5e-324, 1.7976931348623157e308, np.nan, np.inf, -np.inf, 123456789.5, 1e100, -1e-100]])


@pytest.mark.parametrize("spec", ["g1", "g6", "g9", "g12", "g15", "g17", "f0", "f5", "f7", "d"])
def test_obj_numbers_are_pythons_text(rng, spec):
    from o3d_seqcc.io.export.obj_text import fixed_field, general_field, int_field, rows

    x = _adversarial(rng)
    if spec == "d":
        x = np.concatenate([rng.integers(-10 ** 12, 10 ** 12, 5000), [0, 1, -1, 9, 10, 99, 100, 2 ** 62]])
        field, fmt = int_field(x), "%d"
    elif spec[0] == "g":
        field, fmt = general_field(x, int(spec[1:])), f"%.{spec[1:]}g"
    else:
        field, fmt = fixed_field(x, int(spec[1:])), f"%.{spec[1:]}f"
    assert rows([field, "\n"]).decode("ascii") == "".join(f"{fmt % v}\n" for v in x.tolist())


def _python_obj_lines(verts, vt, normals, faces, digits) -> str:
    """The OBJ body as o3d_seqcc wrote it before (Python's % formatting, one page)."""
    def block(prefix, a, fmt):
        return ((prefix + " " + " ".join([fmt] * a.shape[1]) + "\n") * len(a)) % tuple(a.ravel().tolist())
    f1 = np.repeat(faces + 1, 3, axis=1)
    return (block("v", verts, f"%.{digits}g") + block("vt", vt, "%.7f") + block("vn", normals, "%.5f") +
            "usemtl material_0\n" + (("f" + " %d/%d/%d" * 3 + "\n") * len(f1)) % tuple(f1.ravel().tolist()))


@pytest.mark.parametrize("shift", [0.0, 3.2e6])
def test_obj_lines_are_the_python_formatted_obj(rng, monkeypatch, shift):
    from o3d_seqcc.io.export import obj_text

    monkeypatch.setattr(obj_text, "OBJ_CHUNK_ROWS", 1000)  # several chunks
    m, f = 4321, 7000
    verts = rng.normal(size=(m, 3)) * rng.choice([1e-6, 1e-2, 1.0, 30.0], size=(m, 1)) + shift
    verts[:10] = 0.0
    vt, normals = rng.uniform(-0.01, 1.01, size=(m, 2)), rng.normal(size=(m, 3))
    faces = rng.integers(0, m, size=(f, 3))
    from o3d_seqcc.io.export.obj import _digits

    d = _digits(verts)
    got = b"".join(obj_text.obj_lines(verts, vt, normals, faces, np.zeros(f, int), 1, digits=d)).decode("ascii")
    assert got == _python_obj_lines(verts, vt, normals, faces, d)


def test_glb_file_is_glb_bytes(tmp_path, textured):
    assert export_glb(textured, tmp_path / "m.glb").read_bytes() == glb_bytes(textured)


def test_textures_encoded_beside_the_obj_text_give_the_same_files(tmp_path, textured):
    """export_textured_mesh encodes on a thread while the OBJ's text is written: the files of one writer after the
    other; export_obj takes the encoded pages as a callable too."""
    from o3d_seqcc.io.export.textures import _encoded_pages

    out = export_textured_mesh(textured, tmp_path / "a", formats=("glb", "obj"))
    assert list(out) == ["glb", "obj"]
    enc = _encoded_pages(textured, "png", 90, 1, None)
    export_glb(textured, tmp_path / "b" / "mesh.glb", encoded=enc)
    export_obj(textured, tmp_path / "b" / "mesh.obj", encoded=lambda: enc)
    for name in ("mesh.glb", "mesh.obj", "mesh.mtl", "mesh.png"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == ["mesh.glb", "mesh.mtl", "mesh.obj", "mesh.png"]
