"""A distorted scene textured like the undistorted one: COLMAP OPENCV and RADIAL cameras vs PINHOLE.

A synthetic room (two rings of cameras, camera-like photometric changes) is photographed twice
by the same cameras: once by pinhole ones, once through a lens with known distortion
coefficients (the photos ray-cast along the distorted rays: 4 x 4 rays per pixel, box filter,
then a Gaussian optical blur of sigma 0.5 px, as a camera's optics and sensor would). Both are
written as COLMAP text models (``pycolmap``) and run through ``o3d_seqcc.pipeline.run`` with the
defaults toward the room's unchanged photo ``v00`` (``reference="auto"`` may pick a photo with a
strong exposure change, which the whole texture then carries: 15 CIEDE2000 from the albedo at
640x480, although the two runs still agree); the distorted run undistorts its
photos on the fly. Printed per model and resolution:

- texture: mean CIEDE2000 between the two textured meshes rendered from every camera, over the
  pixels that see the mesh (the issue's criterion: within 1), with ``method="none"`` (no
  correction: what the undistortion alone changes), and between the faces' mean colours in those
  renders (the colours without the detail inside each face);
- photos: mean CIEDE2000 between the undistorted photos and the pinhole ones;
- each run's texture against the ground-truth albedo renders;
- reading a photo: undistorted vs plain, median of 20 reads (the cost of the remap).

    python benchmarks/distortion.py [--sizes 160x120,320x240,640x480] [--views 10]
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # this checkout's package, not whichever one is installed

#: COLMAP model -> (its parameters from (f, cx, cy) in COLMAP's pixel convention, OpenCV's coefficients)
MODELS = {
    "PINHOLE": (lambda f, cx, cy: [f, f, cx, cy], None),
    "OPENCV": (lambda f, cx, cy: [f, f, cx, cy, -0.25, 0.08, 0.001, -0.0015], [-0.25, 0.08, 0.001, -0.0015]),
    "RADIAL": (lambda f, cx, cy: [f, cx, cy, -0.2, 0.05], [-0.2, 0.05, 0.0, 0.0]),
}


def photo_rays(K, coeffs, width, height, supersample=4) -> np.ndarray:
    """(H * W * s * s, 2) focal-normalised directions of the sub-pixel samples of a camera with OpenCV
    distortion ``coeffs`` (None: pinhole), inverted exactly (to 1e-6 px) from the photo positions."""
    import cv2

    o = (np.arange(supersample) + 0.5) / supersample - 0.5
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    du, dv = np.meshgrid(o, o)
    pu, pv = (u[..., None, None] + du).ravel(), (v[..., None, None] + dv).ravel()
    if coeffs is None:
        return np.stack([(pu - K[0, 2]) / K[0, 0], (pv - K[1, 2]) / K[1, 1]], 1)
    D = np.asarray(coeffs, dtype=np.float64)
    pix = np.stack([pu, pv], 1).reshape(-1, 1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
    xn = cv2.undistortPoints(pix, K, D, None, None, None, crit).reshape(-1, 2)
    back, _ = cv2.projectPoints(np.c_[xn, np.ones(len(xn))].reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, D)
    assert np.abs(back.reshape(-1, 2) - pix.reshape(-1, 2)).max() < 1e-6  # the rays are exact
    return xn


def render_photo(rc, geom, xn, extrinsic, width, height, *, supersample=4, psf=0.5) -> np.ndarray:
    """The room's albedo along the rays ``xn`` (:func:`photo_rays`) of a camera at ``extrinsic``: (H, W, 3) float."""
    import cv2
    import open3d as o3d

    from o3d_seqcc.synthetic import room

    R, t = extrinsic[:3, :3], extrinsic[:3, 3]
    origin = -R.T @ t
    dirs = np.c_[xn, np.ones(len(xn))] @ R
    rays = np.concatenate([np.broadcast_to(origin, dirs.shape), dirs], 1).astype(np.float32)
    ans = rc.cast_rays(o3d.core.Tensor(rays))
    prim = ans["primitive_ids"].numpy().astype(np.int64)
    hit = np.isfinite(ans["t_hit"].numpy()) & (prim < len(geom.faces))
    fh, d = prim[hit], dirs[hit]
    v0, n = geom.vertices[geom.faces[fh, 0]], geom.normals[geom.faces[fh, 0]]
    pts = origin + (np.einsum("ij,ij->i", v0 - origin, n) / np.einsum("ij,ij->i", d, n))[:, None] * d
    col = np.zeros((len(dirs), 3))
    col[hit] = room._albedo(geom, pts, fh)  # the generator's own surface colours
    col = col.reshape(height, width, supersample * supersample, 3).mean(2)
    return cv2.GaussianBlur(col, (0, 0), psf) if psf > 0 else col


def write_colmap(syn, folder: Path, model: str, *, supersample=4, psf=0.5) -> Path:
    """``syn``'s cameras as a COLMAP text model of ``model`` at ``folder/sparse``, photos in ``folder/images``."""
    import open3d as o3d
    import pycolmap

    from o3d_seqcc.imaging.arrays import img_as_dtype
    from o3d_seqcc.io.images import write_image
    from o3d_seqcc.evaluation.photometric import apply_photometric
    from o3d_seqcc.synthetic import room

    v0 = syn.scene.views[0]
    K, W, H = v0.intrinsic, v0.width, v0.height
    params, coeffs = MODELS[model]
    geom = room.build_geometry(float(syn.metadata["cell_size"]))
    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(o3d.core.Tensor(geom.vertices.astype(np.float32)), o3d.core.Tensor(geom.faces.astype(np.uint32)))
    rec = pycolmap.Reconstruction()
    rec.add_camera_with_trivial_rig(pycolmap.Camera(model=model, width=W, height=H, camera_id=1,
                                                    params=params(K[0, 0], K[0, 2] + 0.5, K[1, 2] + 0.5)))
    (folder / "images").mkdir(parents=True, exist_ok=True)
    xn = photo_rays(K, coeffs, W, H, supersample)
    for i, v in enumerate(syn.scene.views):
        gt = img_as_dtype(render_photo(rc, geom, xn, v.extrinsic, W, H, supersample=supersample, psf=psf), np.uint8)
        prm = syn.transforms[v.name]
        img = gt if i == 0 else img_as_dtype(apply_photometric(gt, prm), np.uint8)
        write_image(folder / "images" / f"{v.name}.png", img)
        E = v.extrinsic
        rec.add_image_with_trivial_frame(pycolmap.Image(name=f"{v.name}.png", camera_id=1, image_id=i + 1),
                                         pycolmap.Rigid3d(pycolmap.Rotation3d(E[:3, :3]), E[:3, 3]))
    (folder / "sparse").mkdir(parents=True, exist_ok=True)
    rec.write_text(str(folder / "sparse"))
    return folder / "sparse"


def texture_delta_e(syn, a, b) -> float:
    """Mean CIEDE2000 between two textured meshes rendered from every camera of ``syn`` (mesh pixels)."""
    from o3d_seqcc.evaluation.metrics import image_delta_e
    from o3d_seqcc.evaluation.render import render_textured

    return float(np.mean([image_delta_e(render_textured(b, v), render_textured(a, v), mask=syn.load_face_ids(k) >= 0)
                          for k, v in enumerate(syn.scene.views)]))


def face_delta_e(syn, a, b) -> float:
    """The same comparison per face: CIEDE2000 of the faces' mean colours in the renders (pixel-weighted),
    which leaves out what the resampling does to the detail within a face."""
    from o3d_seqcc.imaging.arrays import delta_e_2000, img_as_float
    from o3d_seqcc.evaluation.render import render_textured

    des, weights = [], []
    for k, v in enumerate(syn.scene.views):
        fid = syn.load_face_ids(k).ravel()
        ok = fid >= 0
        ids, inv, cnt = np.unique(fid[ok], return_inverse=True, return_counts=True)
        means = []
        for mesh in (a, b):
            img = img_as_float(render_textured(mesh, v)).reshape(-1, 3)[ok]
            means.append(np.stack([np.bincount(inv, img[:, c], len(ids)) for c in range(3)], 1) / cnt[:, None])
        des.append(delta_e_2000(means[0], means[1]))
        weights.append(cnt)
    return float(np.average(np.concatenate(des), weights=np.concatenate(weights)))


def measure(size: tuple[int, int], views: int, root: Path) -> None:
    import o3d_seqcc as sc
    from o3d_seqcc.evaluation.metrics import image_delta_e

    W, H = size
    syn = sc.make_synthetic_scene(root / "syn", n_views=views, width=W, height=H, cell_size=0.15, layout="two-rings")
    scenes, runs = {}, {}
    for model in MODELS:
        sparse = write_colmap(syn, root / model, model)
        scenes[model] = sc.load_scene(sparse, mesh=syn.scene.mesh, image_dir=root / model / "images")
        for method in ("seqcc-global", "none"):
            t = time.perf_counter()
            # defaults, toward the synthetic room's unchanged photo v00 (the truth is its albedo: toward any other
            # reference the whole texture carries that photo's exposure, 15 CIEDE2000 from the truth)
            runs[model, method] = sc.pipeline.run(scenes[model], method=method, reference="v00")
            if method == "seqcc-global":
                print(f"  {W}x{H} {model}: run {time.perf_counter() - t:.1f} s, "
                      f"{len(runs[model, method].correction.unreachable)} views without a correction path")
    gt = [syn.load_gt(k) for k in range(views)]
    masks = [syn.load_face_ids(k) >= 0 for k in range(views)]
    for model in ("OPENCV", "RADIAL"):
        tex = texture_delta_e(syn, runs["PINHOLE", "seqcc-global"].textured, runs[model, "seqcc-global"].textured)
        tex0 = texture_delta_e(syn, runs["PINHOLE", "none"].textured, runs[model, "none"].textured)
        faces = face_delta_e(syn, runs["PINHOLE", "seqcc-global"].textured, runs[model, "seqcc-global"].textured)
        photos = np.mean([image_delta_e(scenes[model].views[k].load_image(), scenes["PINHOLE"].views[k].load_image(),
                                        mask=masks[k]) for k in range(views)])
        from o3d_seqcc.evaluation.render import render_textured

        def vs_gt(res):
            return np.mean([image_delta_e(render_textured(res.textured, v), gt[k], mask=masks[k])
                            for k, v in enumerate(syn.scene.views)])

        v = scenes[model].views[0]
        reads = {}
        for name, fn in (("undistorted", v.load_image), ("plain", lambda: sc.io.images.read_image(v.image))):
            ts = []
            for _ in range(20):
                t = time.perf_counter()
                fn()
                ts.append(time.perf_counter() - t)
            reads[name] = float(np.median(ts))
        print(f"{W}x{H} {model}: texture vs the undistorted run {tex:.2f} CIEDE2000 (method none: {tex0:.2f}; "
              f"face means {faces:.2f}); "
              f"photos {photos:.2f}; vs ground truth {vs_gt(runs[model, 'seqcc-global']):.2f} "
              f"(undistorted run {vs_gt(runs['PINHOLE', 'seqcc-global']):.2f}); read {1e3 * reads['undistorted']:.1f} ms "
              f"vs {1e3 * reads['plain']:.1f} ms plain ({reads['undistorted'] / reads['plain']:.2f}x)")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="160x120,320x240,640x480")
    ap.add_argument("--views", type=int, default=10)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    for s in args.sizes.split(","):
        w, h = (int(x) for x in s.lower().split("x"))
        root = Path(tempfile.mkdtemp(prefix="o3d_seqcc_distortion_"))
        try:
            measure((w, h), args.views, root)
        finally:
            shutil.rmtree(root, ignore_errors=True)
    print("target: texture within 1 CIEDE2000 of the undistorted run (issue 20)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
