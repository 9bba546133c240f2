"""Stray geometry: parts of the mesh far from everything the photos see, which no photo sees either.

Scans carry floating junk: a triangle or a sheet kilometres away, a reconstruction artefact.
Nothing can texture it, and left in it would set the scene's scale (tolerances taken from the
mesh's extent) and take the texture atlas (a 200 m sheet as a fallback chart shrank a room's
texels 16-fold). :func:`stray_faces` finds it: connected components (faces sharing vertices)
with no face usable in any view whose every face lies outside the box of the usable faces and
the cameras, grown by :data:`FAR` (10) times that box's diagonal on every side. :func:`drop_faces`
removes such faces from a mesh and its visibility records (ids renumbered);
:func:`~o3d_seqcc.visibility.compute_visibility` does both and warns with the count.
"""

from __future__ import annotations

import numpy as np

from ..geometry.meshops import bounds

__all__ = ["FAR", "drop_faces", "stray_faces"]


#: a component is far when it lies outside the box of the usable faces and the cameras grown by this many
#: times the box's diagonal on every side (100 km from a room; a room's unseen furniture is never far)
FAR = 10.0


def stray_faces(vertices: np.ndarray, faces: np.ndarray, records, centers: np.ndarray | None = None) -> np.ndarray:
    """(F,) bool: faces of far-away components that no view can use.

    Parameters
    ----------
    vertices : (N, 3) float64
    faces : (F, 3) int64
    records : sequence of ViewRecord
        Per view, the ids of its valid faces and their filter bits (0 = usable).
    centers : (V, 3) float64, optional
        Camera centres (part of the region the photos see).

    Returns
    -------
    (F,) bool
        All False when no face is usable anywhere (nothing to compare with) or nothing is far.
    """
    F = len(faces)
    usable = np.zeros(F, dtype=bool)
    for r in records:
        usable[np.asarray(r.faces)[np.asarray(r.flags) == 0]] = True
    if not usable.any():
        return np.zeros(F, dtype=bool)
    vseen = np.zeros(len(vertices), dtype=bool)
    for k in range(3):
        vseen[faces[usable, k]] = True
    pts = vertices[vseen] if centers is None else np.vstack([vertices[vseen], np.asarray(centers, np.float64)])
    lo, hi = bounds(pts)
    grow = FAR * float(np.linalg.norm(hi - lo))
    lo, hi = lo - grow, hi + grow
    out_v = np.zeros(len(vertices), dtype=bool)
    for a in range(3):
        out_v |= (vertices[:, a] < lo[a]) | (vertices[:, a] > hi[a])
    if not out_v.any():  # the usual case: nothing far at all
        return np.zeros(F, dtype=bool)
    cand = np.flatnonzero(out_v[faces[:, 0]] & ~usable)
    fc = faces[cand]
    hit = np.zeros(len(cand), dtype=bool)  # the face's bounding box misses the grown box
    for a in range(3):
        for outside in (vertices[:, a] < lo[a], vertices[:, a] > hi[a]):
            hit |= outside[fc].all(axis=1)
    far = np.zeros(F, dtype=bool)
    far[cand[hit]] = True
    if not far.any():
        return far
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    # components of the far faces alone; one that shares a vertex with any other face is not apart
    near_v = np.zeros(len(vertices), dtype=bool)
    for k in range(3):
        near_v[faces[~far, k]] = True
    ids = np.flatnonzero(far)
    fv, inv = np.unique(faces[ids], return_inverse=True)
    local = inv.reshape(-1, 3)
    n = len(fv)
    a, b = np.concatenate([local[:, 0], local[:, 1]]), np.concatenate([local[:, 1], local[:, 2]])
    _, label = connected_components(coo_matrix((np.ones(len(a), np.int8), (a, b)), shape=(n, n)), directed=False)
    attached = np.bincount(label, weights=near_v[fv], minlength=label.max() + 1) > 0
    far[ids[attached[label[local[:, 0]]]]] = False
    return far


def drop_faces(mesh, records, drop: np.ndarray):
    """``mesh`` without the faces ``drop`` (and the vertices only they used), and ``records`` renumbered.

    Returns
    -------
    (Mesh, tuple of ViewRecord, float)
        The mesh, the records without the dropped faces (ids of the kept ones), and the largest
        distance of a dropped vertex from the kept ones' bounding box.
    """
    from dataclasses import replace

    from ..scene import Mesh
    from .per_view import DEPTH, MASKED, OBLIQUE, OCCLUDED

    keep = ~np.asarray(drop, dtype=bool)
    faces = np.asarray(mesh.faces)
    used = np.zeros(len(mesh.vertices), dtype=bool)
    used[faces[keep].ravel()] = True
    only_dropped = np.zeros(len(mesh.vertices), dtype=bool)
    only_dropped[faces[~keep].ravel()] = True
    vkeep = ~only_dropped | used
    vnew = np.cumsum(vkeep) - 1
    fnew = np.cumsum(keep) - 1
    lo, hi = mesh.vertices[used].min(axis=0), mesh.vertices[used].max(axis=0)
    gone = mesh.vertices[~vkeep]
    dist = float(np.linalg.norm(np.maximum(np.maximum(lo - gone, gone - hi), 0.0), axis=1).max()) if len(gone) else 0.0
    arrays = [np.ascontiguousarray(a) for a in (mesh.vertices[vkeep], vnew[faces[keep]], mesh.vertex_normals[vkeep])]
    for arr in arrays:
        arr.setflags(write=False)
    out = []
    for r in records:
        k = keep[r.faces]
        flags = r.flags[k]
        info = {**r.info, "valid": int(k.sum()), "occluded": int(np.count_nonzero(flags & OCCLUDED)),
                "depth_inconsistent": int(np.count_nonzero(flags & DEPTH)),
                "oblique": int(np.count_nonzero(flags & OBLIQUE)), "masked": int(np.count_nonzero(flags & MASKED)),
                "usable": int(np.count_nonzero(flags == 0))}
        out.append(replace(r, faces=fnew[r.faces[k]].astype(np.int32), flags=flags, area=r.area[k],
                           cos_angle=r.cos_angle[k], info=info))
    return Mesh(vertices=arrays[0], faces=arrays[1].astype(np.int64), vertex_normals=arrays[2]), tuple(out), dist
