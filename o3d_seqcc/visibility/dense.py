"""The one visibility protocol, and the dense (V, F) arrays for tests and figures only.

Every stage reads a visibility through :class:`VisibilityLike`, the sparse per-view API of
:class:`~o3d_seqcc.visibility.Visibility` (usable face ids and areas per view, all usable
incidences view-major, vertex projections on demand): nothing on the default path builds a
views x faces array. :meth:`DenseViews.to_dense` gives those arrays (:class:`DenseVisibility`)
for tests and figures, and :meth:`DenseViews.from_dense` makes a real visibility from
hand-made dense arrays (tests, your own filters).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Protocol, runtime_checkable

import numpy as np

from ..errors import InputError
from .per_view import DEPTH, OBLIQUE, OCCLUDED, ViewRecord

__all__ = ["DenseViews", "DenseVisibility", "UsableFaces", "VisibilityLike"]


@runtime_checkable
class VisibilityLike(Protocol):  # pragma: no cover - typing only
    """What the stages read of a visibility: the sparse per-view records' API.

    Implemented by :class:`~o3d_seqcc.visibility.Visibility` and by the selection's
    :class:`~o3d_seqcc.texturing.data_costs.ScoredVisibility`. Shapes: ``V`` views, ``F``
    faces, ``N`` vertices, ``nnz`` usable (view, face) incidences.
    """

    mesh: object
    n_views: int
    n_faces: int

    def usable_faces(self, v: int) -> np.ndarray:
        """(k,) int64 ascending ids of the faces usable in view ``v``."""

    def usable_area(self, v: int) -> np.ndarray:
        """(k,) float32 projected areas (px^2) of :meth:`usable_faces` of view ``v``."""

    def usable_entries(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(indptr (V+1,), faces (nnz,), area (nnz,), cos_angle (nnz,))``, view-major."""

    def usable_counts(self) -> np.ndarray:
        """(V,) int64 usable faces per view."""

    def vertex_projection(self, v: int, vertex_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(uv (n, 2) float32, z (n,) float32)`` of some vertices in view ``v``."""

    def face_uv(self, selection: np.ndarray) -> np.ndarray:
        """(F, 3, 2) float64 pixel coordinates of every face's corners in its selected view."""

    def to_dense(self, *, projections: bool = True) -> "DenseVisibility":
        """The dense (V, F) arrays (tests and figures only)."""


@dataclass(frozen=True, eq=False)
class DenseVisibility:
    """A visibility as dense arrays (memory V x F: small scenes, tests and figures).

    Attributes
    ----------
    valid, occluded, depth_inconsistent, oblique, usable : (V, F) bool
    area, cos_angle : (V, F) float32
        Projected face areas (px^2) and cosines, 0 where not valid.
    uv : (V, N, 2) float32 or None
        Pixel coordinates of every vertex (NaN at or behind the camera plane); None when not asked.
    depth : (V, N) float32 or None
        Camera z of every vertex.
    """

    valid: np.ndarray
    occluded: np.ndarray
    depth_inconsistent: np.ndarray
    oblique: np.ndarray
    usable: np.ndarray
    area: np.ndarray
    cos_angle: np.ndarray
    uv: np.ndarray | None = None
    depth: np.ndarray | None = None


class UsableFaces:
    """Shape of a (V, F) ``usable`` face mask: what every per-view visibility record exposes."""

    usable: np.ndarray

    @property
    def n_views(self) -> int:
        return int(self.usable.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.usable.shape[1])


def _record(faces: np.ndarray, area: np.ndarray, cos: np.ndarray, name: str = "") -> ViewRecord:
    k = len(faces)
    return ViewRecord(faces=np.asarray(faces, np.int32), flags=np.zeros(k, np.uint8), area=np.asarray(area, np.float32),
                      cos_angle=np.asarray(cos, np.float32), info={"name": name})


class DenseViews(UsableFaces):
    """The dense views of a :class:`~o3d_seqcc.visibility.Visibility` (built on first access, cached, read-only)
    and its construction from dense arrays."""

    @classmethod
    def from_dense(cls, mesh, usable: np.ndarray, *, uv: np.ndarray | None = None, area: np.ndarray | None = None,
                   cos_angle: np.ndarray | None = None, depth: np.ndarray | None = None,
                   view_names: tuple[str, ...] = ()):
        """A visibility from your own dense per-view arrays (no filter run: ``valid = usable``).

        Parameters
        ----------
        mesh : Mesh
        usable : (V, F) bool
        uv : (V, N, 2) float, optional
            Pixel coordinates of every vertex in every view (needed by the texturing and the
            mappings: :meth:`vertex_projection`); without it the visibility serves the selection only.
        area, cos_angle : (V, F) float, optional
            Projected face areas (px^2; default: from ``uv``, required without it) and cosines (default 1).
        depth : (V, N) float, optional
            Camera z of every vertex (default 1).
        view_names : tuple of str
        """
        usable = np.asarray(usable, dtype=bool)
        if usable.ndim != 2:
            raise InputError(f"usable must be a (V, F) bool array, got shape {usable.shape}")
        V, F = usable.shape
        faces = np.asarray(mesh.faces)
        if F != len(faces):
            raise InputError(f"usable has {F} faces per view but the mesh has {len(faces)}")
        if uv is not None:
            uv = np.asarray(uv, dtype=np.float32)
            if uv.shape != (V, len(mesh.vertices), 2):
                raise InputError(f"uv must be ({V}, {len(mesh.vertices)}, 2) and usable ({V}, {len(faces)}), got "
                                 f"{uv.shape} and {usable.shape}")
        elif area is None:
            raise InputError("from_dense needs uv= (vertex projections) or area= (projected face areas)")
        if area is not None:
            area = np.broadcast_to(np.asarray(area, dtype=np.float32), (V, F))
        cos = None if cos_angle is None else np.broadcast_to(np.asarray(cos_angle, np.float32), (V, F))
        names = tuple(view_names)
        records = []
        for v in range(V):
            ids = np.flatnonzero(usable[v])
            if area is None:  # one view at a time: no (V, F, 3, 2) array
                p = uv[v][faces[ids]].astype(np.float64)
                e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
                a = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
            else:
                a = area[v, ids]
            c = np.ones(len(ids), np.float32) if cos is None else cos[v, ids]
            records.append(_record(ids, a, c, names[v] if v < len(names) else str(v)))
        table = None
        if uv is not None:
            table = (uv, np.ones(uv.shape[:2], np.float32) if depth is None else np.asarray(depth, np.float32))
        return cls(mesh=mesh, records=tuple(records), stats={}, view_names=names, uv_table=table)

    @classmethod
    def from_arrays(cls, mesh, uv: np.ndarray, usable: np.ndarray, *, area: np.ndarray | None = None,
                    cos_angle: np.ndarray | None = None, depth: np.ndarray | None = None,
                    view_names: tuple[str, ...] = ()):
        """:meth:`from_dense` with the vertex projections first (the earlier name)."""
        return cls.from_dense(mesh, usable, uv=uv, area=area, cos_angle=cos_angle, depth=depth, view_names=view_names)

    def to_dense(self, *, projections: bool = True) -> DenseVisibility:
        """The dense (V, F) arrays of this visibility (memory V x F; tests and figures only).

        ``projections=False`` leaves out ``uv`` and ``depth`` (V x N, computed from the cameras).
        """
        return DenseVisibility(valid=self.valid, occluded=self.occluded, depth_inconsistent=self.depth_inconsistent,
                               oblique=self.oblique, usable=self.usable, area=self.area, cos_angle=self.cos_angle,
                               uv=self.uv if projections else None, depth=self.depth if projections else None)

    def stage_masks(self) -> dict[str, np.ndarray]:
        """Cumulative (V, F) masks as in the paper's Figure 3 (a figure: dense).

        Keys ``"valid"``, ``"+occlusion"``, ``"+depth"``, ``"+oblique"`` (= ``usable``).
        """
        return {"valid": self.valid, "+occlusion": self._dense_mask(lambda f: (f & OCCLUDED) == 0),
                "+depth": self._dense_mask(lambda f: (f & (OCCLUDED | DEPTH)) == 0), "+oblique": self.usable}

    def _dense_mask(self, keep) -> np.ndarray:
        M = np.zeros((self.n_views, self.n_faces), dtype=bool)
        for v, r in enumerate(self.records):
            M[v, r.faces[keep(r.flags)]] = True
        M.setflags(write=False)
        return M

    def _dense_values(self, name: str) -> np.ndarray:
        M = np.zeros((self.n_views, self.n_faces), dtype=np.float32)
        for v, r in enumerate(self.records):
            M[v, r.faces] = getattr(r, name)
        M.setflags(write=False)
        return M

    @cached_property
    def valid(self) -> np.ndarray:
        return self._dense_mask(lambda f: np.ones(len(f), bool))

    @cached_property
    def occluded(self) -> np.ndarray:
        return self._dense_mask(lambda f: (f & OCCLUDED) != 0)

    @cached_property
    def depth_inconsistent(self) -> np.ndarray:
        return self._dense_mask(lambda f: (f & DEPTH) != 0)

    @cached_property
    def oblique(self) -> np.ndarray:
        return self._dense_mask(lambda f: (f & OBLIQUE) != 0)

    @cached_property
    def usable(self) -> np.ndarray:
        return self._dense_mask(lambda f: f == 0)

    @cached_property
    def area(self) -> np.ndarray:
        return self._dense_values("area")

    @cached_property
    def cos_angle(self) -> np.ndarray:
        return self._dense_values("cos_angle")

    def _dense_projection(self) -> tuple[np.ndarray, np.ndarray]:
        if self.uv_table is not None:
            return self.uv_table
        N = len(self.mesh.vertices)
        uv = np.empty((self.n_views, N, 2), np.float32)
        z = np.empty((self.n_views, N), np.float32)
        allv = np.arange(N)
        for v in range(self.n_views):
            uv[v], z[v] = self.vertex_projection(v, allv)
        return uv, z

    @cached_property
    def uv(self) -> np.ndarray:
        out = np.array(self._dense_projection()[0])
        out.setflags(write=False)
        return out

    @cached_property
    def depth(self) -> np.ndarray:
        out = np.array(self._dense_projection()[1])
        out.setflags(write=False)
        return out
