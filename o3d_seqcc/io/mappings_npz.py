"""Pairwise mappings in ``.npz`` files (format ``o3d_seqcc.mappings/1``).

Two layouts: ``"arrays"`` (every pair's arrays concatenated) and ``"compact"`` (what the pairs
are built from: per-vertex projections and bit-packed usable faces, about 10x smaller for big
meshes). :func:`save_mappings` writes either atomically, :func:`load_mappings` reads both.
"""

from __future__ import annotations

import io
import json
import os
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..mappings.compute import Mappings
from ..mappings.pairs import LazyPairs, PairMapping, PairSource
from ..scene import Mesh
from ..visibility.compute import Visibility
from .atomic import atomic_write_bytes
from .json_files import to_jsonable

__all__ = ["load_mappings", "save_mappings"]


def save_mappings(mappings: Mappings, path: str | os.PathLike, *, format: str = "auto", dtype: str = "float32") -> Path:
    """Write mappings to an ``.npz`` file atomically; read it back with :func:`load_mappings`.

    Parameters
    ----------
    mappings : Mappings
    path : path-like
    format : {"auto", "compact", "arrays"}, default "auto"
        ``"arrays"``: every pair's arrays concatenated: ``pairs`` (P, 2) int32, ``offsets``
        (P+1,) int64, ``counts`` (P,), ``uv_a`` / ``uv_b`` (M, 2) in ``dtype``, ``face_ids``
        (M,) int64 (slice ``offsets[i]:offsets[i+1]`` is pair ``pairs[i]``), ``weights``
        (M, 3) float32 when every pair has them. ``"compact"`` (mappings from
        :func:`compute_mappings` only): what the pairs are built from: per-vertex ``uv``
        (V, N, 2) float32 and ``depth`` (V, N) (the visibility's dense views, computed for the
        file), bit-packed ``usable`` (V, F) faces, the mesh
        ``vertices`` / ``faces``, dense ``level`` and the face mask of a split, about 10x
        smaller for big meshes. ``"auto"``: compact when possible.
        Both have ``format``, ``layout``, ``view_names``, ``mode``, ``pairs``, ``counts``
        and ``filter_stats`` (JSON).
    dtype : str, default "float32"
        Storage type of ``uv_a`` / ``uv_b`` in the arrays layout (float32 keeps ~6e-5 px at
        1000 px).
    """
    if format not in ("auto", "compact", "arrays"):
        raise ValueError(f"unknown format {format!r}; valid: 'auto', 'compact', 'arrays'")
    lazy = isinstance(mappings.pairs, LazyPairs)
    if format == "compact" and not lazy:
        raise ValueError("the compact layout needs mappings from compute_mappings (lazy pairs)")
    keys = list(mappings.pairs.keys())
    data: dict[str, np.ndarray] = {
        "format": np.array("o3d_seqcc.mappings/1"),
        "view_names": np.array(mappings.view_names, dtype=str),
        "mode": np.array(mappings.mode),
        "pairs": np.array(keys, dtype=np.int32).reshape(-1, 2),
        "counts": np.array([mappings.counts[k] for k in keys], dtype=np.int64),
        "filter_stats": np.array(json.dumps(to_jsonable(mappings.filter_stats))),
    }
    if mappings.image_sizes is not None:  # what t_npm="auto" is derived from
        data["image_sizes"] = np.array(mappings.image_sizes, dtype=np.int64).reshape(-1, 2)
    if lazy and format != "arrays":
        src = mappings.pairs.source
        vis = src.vis
        data.update(
            layout=np.array("compact"),
            uv=np.asarray(vis.uv, dtype=np.float32),
            depth=np.asarray(vis.depth, dtype=np.float32),
            usable=np.packbits(vis.usable, axis=1),
            n_faces=np.array(vis.n_faces),
            vertices=np.asarray(vis.mesh.vertices, dtype=np.float64),
            faces=np.asarray(vis.mesh.faces, dtype=np.int64),
        )
        if src.level is not None:
            data["level"] = src.level.astype(np.int16)
        data["sample_spacing"] = np.array(float(getattr(src, "spacing", 3.0)))
        if src.face_mask is not None:
            data["face_mask"] = np.packbits(src.face_mask)
    else:
        pms = [mappings.pairs[k] for k in keys]
        offsets = np.concatenate([[0], np.cumsum([pm.n for pm in pms])]).astype(np.int64)

        def cat(arrs, shape, dt):
            return np.concatenate(arrs).astype(dt) if arrs else np.zeros(shape, dt)

        data.update(
            layout=np.array("arrays"),
            offsets=offsets,
            uv_a=cat([pm.uv_a for pm in pms], (0, 2), dtype),
            uv_b=cat([pm.uv_b for pm in pms], (0, 2), dtype),
            face_ids=cat([pm.face_ids for pm in pms], (0,), np.int64),
        )
        if pms and all(pm.weights is not None for pm in pms):
            data["weights"] = cat([pm.weights for pm in pms], (0, 3), np.float32)
    buf = io.BytesIO()
    np.savez(buf, **data)
    return atomic_write_bytes(path, buf.getvalue())


def load_mappings(path: str | os.PathLike) -> Mappings:
    """Read mappings written by :func:`save_mappings` (``visibility`` is None).

    Raises
    ------
    InputError
        Missing file or not a mappings file.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"mappings file not found: {path}")
    try:
        z = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as e:
        raise InputError(f"{path}: not a .npz mappings file ({e}); write one with `o3d-seqcc mappings`") from None
    with z:
        files = set(z.files)
        need = {"view_names", "mode", "pairs", "counts"}
        layout = str(z["layout"]) if "layout" in files else "arrays"
        need |= {"uv", "depth", "usable", "vertices", "faces", "n_faces"} if layout == "compact" else {
            "offsets", "uv_a", "uv_b", "face_ids"}
        missing = need - files
        if missing:
            raise InputError(
                f"{path}: not a mappings file (missing {sorted(missing)}); write one with `o3d-seqcc mappings`"
            )
        keys = [tuple(int(x) for x in r) for r in z["pairs"]]
        counts = {k: int(c) for k, c in zip(keys, z["counts"])}
        stats = json.loads(str(z["filter_stats"])) if "filter_stats" in files else {}
        names = tuple(str(n) for n in z["view_names"])
        mode = str(z["mode"])
        sizes = tuple(map(tuple, z["image_sizes"].tolist())) if "image_sizes" in files else None
        if layout == "compact":
            F = int(z["n_faces"])
            usable = np.unpackbits(z["usable"], axis=1, count=F).astype(bool)
            vertices = z["vertices"]  # the parts of a Visibility that pair building needs: one real Visibility
            mesh = Mesh(vertices=vertices, faces=z["faces"], vertex_normals=np.zeros_like(vertices))
            vis = Visibility.from_dense(mesh, usable, uv=z["uv"], depth=z["depth"], view_names=tuple(names))
            level = z["level"].astype(np.int64) if "level" in files else None
            face_mask = np.unpackbits(z["face_mask"], count=F).astype(bool) if "face_mask" in files else None
            spacing = float(z["sample_spacing"]) if "sample_spacing" in files else 3.0
            src = PairSource(vis, mode, level, face_mask, spacing=spacing)
            return Mappings(
                pairs=LazyPairs(src, keys), view_names=names, mode=mode, filter_stats=stats, counts=counts,
                image_sizes=sizes,
            )
        off = z["offsets"]
        uv_a, uv_b, fid = z["uv_a"].astype(np.float64), z["uv_b"].astype(np.float64), z["face_ids"]
        w = z["weights"] if "weights" in files else None
        pairs = {}
        for i, (a, b) in enumerate(keys):
            s = slice(int(off[i]), int(off[i + 1]))
            pairs[(a, b)] = PairMapping(a, b, uv_a[s], uv_b[s], fid[s], None if w is None else w[s])
    return Mappings(pairs=pairs, view_names=names, mode=mode, filter_stats=stats, counts=counts, image_sizes=sizes)
