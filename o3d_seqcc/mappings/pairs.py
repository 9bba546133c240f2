"""One pair of views' mappings, and the lazy machinery that builds them from a visibility.

:class:`PairMapping` holds the mappings between two views; :class:`PairSource` builds them on
demand from the two views' sparse records of a :class:`~o3d_seqcc.visibility.Visibility` (the
faces usable in both, their corners projected from the cameras)
(vertex mode: the three vertices of every face usable in both views; dense mode: a fixed
barycentric pattern per subdivision level, perspective-correct; surface mode: points on the
shared surface at a fixed spacing in pixels, so their number follows the shared area, not the
tessellation), and :class:`LazyPairs` is the read-only ``{(a, b): PairMapping}`` that builds a
pair when it is read (LRU-cached).

Counts (:meth:`PairSource.counts`): vertex and dense mode count mappings, surface mode counts pixels
of shared surface (:mod:`~o3d_seqcc.mappings.counting`).
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Mapping as _MappingABC
from dataclasses import dataclass
from typing import Any, Iterable, Iterator

import numpy as np

from ..imaging.sequences import LRUCache
from .counting import shared_area, shared_counts
from .sampling import SURFACE_MAX_LEVEL, bary_table, level_dtype, locate, project_points, tri_area

__all__ = ["BATCH_PAIRS", "SURFACE_MAX_LEVEL", "LazyPairs", "Pair", "PairMapping", "PairSource", "norm_key",
           "thinned", "thinned_many"]

Pair = tuple[int, int]

#: pairs planned together by :func:`thinned_many` (a task of its local threads)
BATCH_PAIRS = 32
#: mappings computed together by :meth:`PairSource.thinned_batch` (~5 MB of temporaries)
BATCH_MAPPINGS = 2**15


@dataclass(frozen=True, eq=False)
class PairMapping:
    """The mappings between two views.

    Attributes
    ----------
    a, b : int
        View indices (``a < b`` inside :class:`Mappings`).
    uv_a, uv_b : (n, 2) float64
        Pixel coordinates of the same surface points in views ``a`` and ``b``.
    face_ids : (n,) int64
        Mesh face of each mapping (each face appears 3 times in ``"vertices"`` mode).
    weights : (n, 3) float32, optional
        Barycentric coordinates of each mapping's surface point within its face (``"dense"``
        mode; None in ``"vertices"`` mode, where mapping ``3 i + j`` is vertex ``j`` of face
        ``face_ids[3 i]``); the world point is
        ``(weights[:, :, None] * vertices[faces[face_ids]]).sum(1)``.
    """

    a: int
    b: int
    uv_a: np.ndarray
    uv_b: np.ndarray
    face_ids: np.ndarray
    weights: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "a", int(self.a))
        object.__setattr__(self, "b", int(self.b))
        uv_a = np.asarray(self.uv_a, dtype=np.float64).reshape(-1, 2)
        uv_b = np.asarray(self.uv_b, dtype=np.float64).reshape(-1, 2)
        fid = np.asarray(self.face_ids, dtype=np.int64).reshape(-1)
        if not (len(uv_a) == len(uv_b) == len(fid)):
            raise ValueError(
                f"PairMapping({self.a}, {self.b}): uv_a, uv_b and face_ids lengths differ "
                f"({len(uv_a)}, {len(uv_b)}, {len(fid)})"
            )
        object.__setattr__(self, "uv_a", uv_a)
        object.__setattr__(self, "uv_b", uv_b)
        object.__setattr__(self, "face_ids", fid)
        if self.weights is not None:
            w = np.asarray(self.weights, dtype=np.float32).reshape(-1, 3)
            if len(w) != len(fid):
                raise ValueError(f"PairMapping({self.a}, {self.b}): weights length {len(w)} != {len(fid)}")
            object.__setattr__(self, "weights", w)

    @property
    def n(self) -> int:
        """Number of mappings."""
        return int(len(self.face_ids))

    @property
    def key(self) -> Pair:
        return (self.a, self.b)

    def swapped(self) -> "PairMapping":
        """The same mappings seen from ``b`` to ``a``."""
        return PairMapping(self.b, self.a, self.uv_b, self.uv_a, self.face_ids, self.weights)

    def take(self, index: np.ndarray) -> "PairMapping":
        """A subset (boolean mask or integer index over the n mappings)."""
        w = None if self.weights is None else self.weights[index]
        return PairMapping(self.a, self.b, self.uv_a[index], self.uv_b[index], self.face_ids[index], w)

    def __repr__(self) -> str:
        return f"PairMapping(a={self.a}, b={self.b}, n={self.n})"


def thinned(pairs: Any, key: Any, pick) -> tuple[int, PairMapping]:
    """``(n, pairs[key].take(pick(n)))`` for any ``{pair: PairMapping}`` (:meth:`LazyPairs.thinned`: only the
    picked mappings built); ``pick(n)`` gives ascending indices, or None for all ``n``."""
    if isinstance(pairs, LazyPairs):
        return pairs.thinned(key, pick)
    pm = pairs[key]
    idx = pick(pm.n)
    return pm.n, (pm if idx is None else pm.take(idx))


def thinned_many(pairs: Any, keys: Iterable[Any], pick, *, n_jobs: int | None = None,
                 batch_pairs: int | None = None) -> Iterator[tuple[int, PairMapping]]:
    """:func:`thinned` of every key of ``keys``, yielded in their order: lazy pairs are planned and their
    picked mappings built ``batch_pairs`` (default :data:`BATCH_PAIRS`) pairs at a time, in vectorised
    passes on local threads (``n_jobs``, joblib semantics) -- the same values as one :func:`thinned` per pair."""
    keys = [norm_key(k) for k in keys]
    if not isinstance(pairs, LazyPairs):
        for k in keys:
            yield thinned(pairs, k, pick)
        return
    from .._shared.parallel import LocalExecutor

    step = max(1, int(batch_pairs or BATCH_PAIRS))
    batches = [keys[i : i + step] for i in range(0, len(keys), step)]
    for part in LocalExecutor(n_jobs).imap(pairs.thinned_batch, batches, pick, desc="pairs", unit="batch"):
        yield from part


def norm_key(key: Any) -> Pair:
    """``(a, b)`` as a pair of ints; anything else raises ``KeyError``."""
    try:
        a, b = key
        return int(a), int(b)
    except (TypeError, ValueError):
        raise KeyError(key) from None


class LazyPairs(_MappingABC):
    """Read-only ``{(a, b): PairMapping}`` whose values are built on access (LRU-cached)."""

    def __init__(self, source: "PairSource", keys: Iterable[Pair], *, cache_size: int = 8) -> None:
        self.source = source
        self._keys = sorted(norm_key(k) for k in keys)
        self._keyset = set(self._keys)
        self._cache: OrderedDict[Pair, PairMapping] = OrderedDict()
        self._cache_size = int(cache_size)
        self._lock = threading.Lock()

    def __getitem__(self, key: Any) -> PairMapping:
        k = norm_key(key)
        if k not in self._keyset:
            raise KeyError(key)
        with self._lock:
            pm = self._cache.get(k)
            if pm is not None:
                self._cache.move_to_end(k)
                return pm
        pm = self.source.build(*k)
        if self._cache_size > 0:
            with self._lock:
                self._cache[k] = pm
                while len(self._cache) > self._cache_size:
                    self._cache.popitem(last=False)
        return pm

    def thinned(self, key: Any, pick) -> tuple[int, PairMapping]:
        """``(n, the mappings at pick(n))`` of a pair of ``n`` mappings (``pick(n)``: ascending indices, or None
        for all): the same values as ``self[key].take(pick(n))``, but an uncached pair is sized and only the
        picked mappings built (the correction's 8000 and Table 2's 200 of a pair's 10^4-10^5)."""
        k = norm_key(key)
        if k not in self._keyset:
            raise KeyError(key)
        with self._lock:
            pm = self._cache.get(k)
        if pm is None and hasattr(self.source, "thinned"):
            return self.source.thinned(*k, pick)
        pm = self[k] if pm is None else pm
        idx = pick(pm.n)
        return pm.n, (pm if idx is None else pm.take(idx))

    def thinned_batch(self, keys: list[Any], pick) -> list[tuple[int, PairMapping]]:
        """:meth:`thinned` of several pairs, the uncached ones built together (:meth:`PairSource.thinned_batch`)."""
        keys = [norm_key(k) for k in keys]
        for k in keys:
            if k not in self._keyset:
                raise KeyError(k)
        with self._lock:
            held = {k: self._cache[k] for k in keys if k in self._cache}
        if not hasattr(self.source, "thinned_batch"):
            return [self.thinned(k, pick) for k in keys]
        built = iter(self.source.thinned_batch([k for k in keys if k not in held], pick))
        out = []
        for k in keys:
            if k in held:
                idx = pick(held[k].n)
                out.append((held[k].n, held[k] if idx is None else held[k].take(idx)))
            else:
                out.append(next(built))
        return out

    def __contains__(self, key: object) -> bool:
        try:
            return norm_key(key) in self._keyset
        except KeyError:
            return False

    def __iter__(self) -> Iterator[Pair]:
        return iter(self._keys)

    def __len__(self) -> int:
        return len(self._keys)

    def __repr__(self) -> str:
        return f"<lazy pairs: {len(self)} pairs>"

    def __getstate__(self) -> dict:
        d = self.__dict__.copy()
        d["_cache"] = OrderedDict()
        del d["_lock"]
        return d

    def __setstate__(self, d: dict) -> None:
        self.__dict__.update(d)
        self._lock = threading.Lock()


#: byte budget of a :class:`PairSource`'s per-view face levels (one byte per usable face and view; rebuilt when dropped)
LEVEL_CACHE_BYTES = 64 * 2**20


class PairSource:
    """Builds the mappings of one pair from the per-view usable faces of a visibility.

    ``vis`` is a :class:`~o3d_seqcc.visibility.Visibility` (or anything with ``n_views``,
    ``n_faces``, ``mesh``, ``usable_faces(v)`` and ``vertex_projection(v, vertex_ids)``;
    ``usable_area(v)`` is used when present). ``spacing`` is the surface mode's sample spacing
    in pixels.

    A pair is planned from per-view data only (:meth:`view_levels`: every usable face's sampling level
    in the view, computed once per view), and only the faces of the mappings asked for are projected,
    so sizing a pair and building a few thousand of its mappings costs about one pass over the two
    views' usable faces.
    """

    def __init__(self, vis, mode: str, level: np.ndarray | None, face_mask: np.ndarray | None, *,
                 spacing: float = 3.0) -> None:
        self.vis = vis
        self.mode = mode
        self.level = level  # (F,) int per face (dense mode)
        self.face_mask = face_mask  # (F,) bool or None
        self.spacing = float(spacing)
        if mode == "dense":
            self.table, self.start, self.count = bary_table(int(level.max()) if len(level) else 1)
        elif mode == "surface":  # level 0: the vertices alone; level L: the vertices and L^2 centroids
            table, start, count = bary_table(SURFACE_MAX_LEVEL)
            self.table = np.concatenate([np.eye(3), table])
            self.start, self.count = start + 3, count.copy()
            self.start[0], self.count[0] = 0, 3
        else:
            self.count = np.array([0, 3])
        self._level_dtype = level_dtype(len(self.count) - 1)
        if mode != "vertices":  # the table's columns (gathered per mapping) and its float32 copy (the weights kept)
            self._table_columns = [np.ascontiguousarray(self.table[:, j]) for j in range(3)]
            self._table32 = self.table.astype(np.float32)
        self._levels = LRUCache(LEVEL_CACHE_BYTES)

    def usable_faces(self, v: int) -> np.ndarray:
        """(k,) int64 ascending faces usable in view ``v`` (within the face mask)."""
        ids = self.vis.usable_faces(v)
        return ids if self.face_mask is None else ids[self.face_mask[ids]]

    def usable_area(self, v: int) -> np.ndarray:
        """(k,) float64 projected areas (px^2) of :meth:`usable_faces` in view ``v``."""
        a = np.asarray(self.vis.usable_area(v), dtype=np.float64)
        if self.face_mask is not None:
            a = a[self.face_mask[self.vis.usable_faces(v)]]
        return a

    def usable(self) -> np.ndarray:
        """(V, F) bool usable faces within the face mask (dense: small scenes only)."""
        U = np.zeros((self.vis.n_views, self.vis.n_faces), dtype=bool)
        for v in range(self.vis.n_views):
            U[v, self.usable_faces(v)] = True
        return U

    def per_face(self) -> np.ndarray:
        F = self.vis.n_faces
        if self.mode == "vertices":
            return np.full(F, 3, dtype=np.int64)
        return self.count[self.level]

    def counts(self) -> dict[Pair, int]:
        """Per pair: the number of mappings, or (surface mode) the shared area in pixels (rounded)."""
        rows = [self.usable_faces(v) for v in range(self.vis.n_views)]
        if self.mode == "vertices":
            C = 3 * shared_counts(rows, self.vis.n_faces)
        elif self.mode == "surface":
            M = shared_area(rows, [self.usable_area(v) for v in range(len(rows))], self.vis.n_faces)
            C = np.rint(np.minimum(M, M.T)).astype(np.int64)
        else:
            C = shared_counts(rows, self.vis.n_faces, weights=self.count[self.level])
        a, b = np.triu_indices(len(rows), k=1)
        c = C[a, b]
        return {(int(i), int(j)): int(n) for i, j, n in zip(a, b, c) if n > 0}

    def faces(self, a: int, b: int) -> np.ndarray:
        """(m,) int64 ascending faces usable in both views."""
        ua, ub = self.usable_faces(a), self.usable_faces(b)
        mark = np.zeros(self.vis.n_faces, dtype=bool)
        mark[ua] = True
        return ub[mark[ub]]

    def _area_levels(self, area: np.ndarray) -> np.ndarray:
        """Surface mode: the subdivision level of faces from their (m,) projected areas (px^2) in a view.

        Every face gives its 3 vertices (as the paper's mappings); a face whose smaller projection
        of the two views holds ``m = area / spacing^2 >= 1`` sample cells gives, besides, the
        centroids of the ``L^2`` sub-triangles of a level-``L`` subdivision, ``L = clip(round(
        sqrt(m)), 1, SURFACE_MAX_LEVEL)``: so a large face is sampled at the photos' resolution
        and a dense mesh as the paper samples it (on Fountain the vertices' weighting of the
        detailed surface scores better against the semi-real truth than area samples alone:
        2.78 vs 2.86 CIEDE2000, benchmarks/table2.py). The level is a non-decreasing function of
        the area, so a pair's level, that of its smaller projection, is the smaller of its two
        views' levels: each view's are computed once (:meth:`view_levels`).
        """
        m = area / self.spacing**2
        return np.where(m >= 1.0, np.clip(np.rint(np.sqrt(np.maximum(m, 1.0))), 1, SURFACE_MAX_LEVEL),
                        0).astype(self._level_dtype)

    def view_levels(self, v: int) -> tuple[np.ndarray, np.ndarray]:
        """The faces usable in view ``v`` and their sampling level there (cached per view).

        Returns
        -------
        faces : (k,) int64
            :meth:`usable_faces`.
        level : (k,) small signed int
            Surface mode: the level of the face's projection in ``v`` (:meth:`_area_levels`);
            dense mode: the face's level; vertex mode: 1. A pair's level is the smaller of its two views'.
        """
        def make() -> tuple[np.ndarray, np.ndarray]:
            ids = self.usable_faces(v)
            if self.mode == "surface":
                tri = np.asarray(self.vis.mesh.faces)[ids].reshape(-1)
                uv = self.vis.vertex_projection(v, tri)[0].reshape(-1, 3, 2)
                return ids, self._area_levels(tri_area(uv.astype(np.float64)))
            if self.mode == "dense":
                return ids, self.level[ids].astype(self._level_dtype)
            return ids, np.ones(len(ids), dtype=self._level_dtype)

        return self._levels.get(v, make)

    def _pair_levels(self, a: int, b: int, mark: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(faces usable in both views, ascending (m,) int64; their level in the pair (m,)). ``mark``: an
        (F,) array holding view ``a``'s levels and -1 elsewhere (several pairs of ``a`` reuse it)."""
        ib, lb = self.view_levels(b)
        if mark is None:
            ia, la = self.view_levels(a)
            mark = np.full(self.vis.n_faces, -1, dtype=self._level_dtype)
            mark[ia] = la
        at_b = mark[ib]
        both = at_b >= 0
        return ib[both], np.minimum(at_b[both], lb[both])

    def _plan(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The pair's faces grouped by level: (faces (m,), level (m,) ascending, first mapping of every
        face (m + 1,)); the mappings are face after face, each its level's pattern (the vertices alone in
        vertex mode). Within a level the faces are ascending."""
        k, lev = self._pair_levels(a, b)
        if self.mode == "vertices":
            return k, np.ones(len(k), np.int64), 3 * np.arange(len(k) + 1)
        order = np.argsort(lev, kind="stable")
        lev = lev[order].astype(np.int64)
        return k[order], lev, np.concatenate([[0], np.cumsum(self.count[lev])])

    def locate_batch(self, keys: list[Pair], pick) -> list[tuple[int, np.ndarray, np.ndarray]]:
        """Where the picked mappings of several pairs are, without computing them: per pair ``(n, face (s,),
        point (s,))`` int32, mapping ``i`` being row ``point[i]`` of the barycentric table (vertex mode: vertex
        ``point[i]``) on face ``face[i]``, a face's mappings consecutive (:meth:`points` gives their positions).
        Each pair is sized from its two views' levels (``keys`` sorted by their first view share its levels)."""
        out = []
        mark, held = None, None
        for a, b in keys:
            if held != a:  # view a's levels on the faces, for all its pairs
                if mark is None:
                    mark = np.full(self.vis.n_faces, -1, dtype=self._level_dtype)
                elif held is not None:
                    mark[self.view_levels(held)[0]] = -1
                ia, la = self.view_levels(a)
                mark[ia] = la
                held = a
            k, lev = self._pair_levels(a, b, mark)
            n, face, level, point = locate(k, lev, self.count, pick, sort=self.mode != "vertices")
            row = point if self.mode == "vertices" else self.start[level] + point
            out.append((n, face.astype(np.int32), row.astype(np.int32)))
        return out

    def points(self, views: np.ndarray, bounds: np.ndarray, face: np.ndarray, point: np.ndarray) -> np.ndarray:
        """(M, 2) float64 pixel positions of located mappings (:meth:`locate_batch`) in runs: run ``p``, the
        mappings ``bounds[p]:bounds[p + 1]``, in view ``views[p]`` (bit for bit :meth:`build`'s values)."""
        face = np.asarray(face, np.int64)
        point = np.asarray(point, np.int64)
        faces = np.asarray(self.vis.mesh.faces)
        out = np.empty((len(face), 2))
        if self.mode != "vertices":  # runs in chunks of about BATCH_MAPPINGS points (their temporaries in cache)
            bounds = np.asarray(bounds, np.int64)
            cuts = np.unique(np.searchsorted(bounds, np.arange(0, bounds[-1], BATCH_MAPPINGS), side="right") - 1)
            for r0, r1 in zip(cuts, np.append(cuts[1:], len(bounds) - 1)):
                s0, s1 = bounds[r0], bounds[r1]
                out[s0:s1] = project_points(self.vis.vertex_projection, faces, views[r0:r1], bounds[r0 : r1 + 1] - s0,
                                            face[s0:s1], [np.take(col, point[s0:s1]) for col in self._table_columns])
            return out
        view_of = np.repeat(np.asarray(views, np.int64), np.diff(bounds))
        for v in np.unique(view_of):
            rows = np.flatnonzero(view_of == v)
            out[rows] = self.vis.vertex_projection(int(v), faces[face[rows], point[rows]])[0]
        return out

    def thinned_batch(self, keys: list[Pair], pick) -> list[tuple[int, PairMapping]]:
        """:meth:`thinned` of several pairs in vectorised passes (:meth:`locate_batch`, then the mappings of
        up to :data:`BATCH_MAPPINGS` of them computed together by :meth:`points`)."""
        out: list = []
        parts: list[tuple] = []  # (a, b, n, face, point) of the pairs not built yet
        pending = 0

        def flush() -> None:
            out.extend(zip((p[2] for p in parts), self._build_located(parts)))
            parts.clear()

        for (a, b), located in zip(keys, self.locate_batch(keys, pick)):
            parts.append((a, b) + located)
            pending += len(located[1])
            if pending >= BATCH_MAPPINGS:
                flush()
                pending = 0
        if parts:
            flush()
        return out

    def size(self, a: int, b: int) -> int:
        """The number of mappings :meth:`build` gives the pair, without building them."""
        return int(self._plan(a, b)[2][-1])

    def thinned(self, a: int, b: int, pick) -> tuple[int, PairMapping]:
        """``(n, build(a, b).take(pick(n)))`` with only the picked mappings built (``pick(n)``: ascending
        indices, or None for all ``n``)."""
        plan = self._plan(a, b)
        n = int(plan[2][-1])
        idx = pick(n)
        return n, self._build(a, b, plan, None if idx is None else np.asarray(idx, np.int64).reshape(-1))

    def build(self, a: int, b: int, index: np.ndarray | None = None) -> PairMapping:
        """The pair's mappings; ``index`` (ascending ints): only those of them (the same values as
        ``build(a, b).take(index)``: each mapping computed by the same arithmetic, the others not at all)."""
        return self._build(a, b, self._plan(a, b), None if index is None else np.asarray(index, np.int64).reshape(-1))

    def _build(self, a: int, b: int, plan: tuple, index: np.ndarray | None) -> PairMapping:
        """:meth:`build` from :meth:`_plan`'s groups. Mapping ``i`` is point ``i - first[f]`` of face ``f``'s
        pattern (a row of the barycentric table), projected perspective-correctly (:meth:`_build_located`)."""
        k, lev, first = plan
        if self.mode != "vertices" and index is None:
            return self._build_all(a, b, plan)
        sel = np.arange(first[-1]) if index is None else index
        f = np.searchsorted(first, sel, side="right") - 1  # the face of every mapping
        row = sel - first[f] if self.mode == "vertices" else self.start[lev[f]] + sel - first[f]
        return self._build_located([(a, b, int(first[-1]), k[f], row)])[0]

    def _build_located(self, parts: list[tuple]) -> list[PairMapping]:
        """The located mappings (:meth:`locate_batch`) of one or several pairs ``(a, b, n, face, point)``, all
        at once (:meth:`points` in each pair's two views)."""
        size = np.array([len(p[3]) for p in parts], dtype=np.int64)
        bounds = np.concatenate([[0], np.cumsum(size)])
        face = np.concatenate([p[3] for p in parts]).astype(np.int64, copy=False)
        point = np.concatenate([p[4] for p in parts]).astype(np.int64, copy=False)
        uv = [self.points(np.array([p[side] for p in parts], np.int64), bounds, face, point) for side in (0, 1)]
        W32 = None if self.mode == "vertices" else self._table32[point]
        return [PairMapping(p[0], p[1], uv[0][s0:s1], uv[1][s0:s1], face[s0:s1], None if W32 is None else W32[s0:s1])
                for p, s0, s1 in zip(parts, bounds[:-1], bounds[1:])]

    def _build_all(self, a: int, b: int, plan: tuple) -> PairMapping:
        """Every mapping of the pair, level group by level group (each group's faces times its fixed
        pattern, broadcast: faster than :meth:`_build`'s per-mapping gathers when all are wanted)."""
        k, lev, first = plan
        tri, proj = np.asarray(self.vis.mesh.faces)[k].reshape(-1), {}
        for v in (a, b):  # every face's corners: (m, 3, 2) pixels, (m, 3) depths, float64 of the float32 projections
            uv, z = self.vis.vertex_projection(v, tri)
            proj[v] = (uv.reshape(-1, 3, 2).astype(np.float64), z.reshape(-1, 3).astype(np.float64))
        bounds = np.flatnonzero(np.diff(lev)) + 1
        uv_out: dict[int, list] = {a: [], b: []}
        fids, ws = [], []
        for s0, s1 in zip(np.concatenate([[0], bounds]), np.concatenate([bounds, [len(k)]])):
            if s1 <= s0:
                continue
            L = int(lev[s0])  # (surface mode: level 0 = the vertices alone)
            Wl = self.table[self.start[L] : self.start[L] + self.count[L]]  # (p, 3)
            for v in (a, b):
                z = proj[v][1][s0:s1]  # (m, 3)
                uvz = proj[v][0][s0:s1] * z[:, :, None]  # (m, 3, 2)
                num, den = np.zeros((s1 - s0, len(Wl), 2)), np.zeros((s1 - s0, len(Wl)))
                for j in range(3):
                    num += Wl[None, :, j, None] * uvz[:, None, j, :]
                    den += Wl[None, :, j] * z[:, None, j]
                uv_out[v].append((num / den[:, :, None]).reshape(-1, 2))
            fids.append(np.repeat(k[s0:s1], len(Wl)))
            ws.append(np.broadcast_to(Wl.astype(np.float32), (s1 - s0,) + Wl.shape).reshape(-1, 3))
        if not fids:
            e2 = np.zeros((0, 2))
            return PairMapping(a, b, e2, e2, np.zeros(0, np.int64), np.zeros((0, 3), np.float32))
        return PairMapping(a, b, np.concatenate(uv_out[a]), np.concatenate(uv_out[b]), np.concatenate(fids),
                           np.concatenate(ws))

    def with_mask(self, face_mask: np.ndarray) -> "PairSource":
        fm = face_mask if self.face_mask is None else (self.face_mask & face_mask)
        src = PairSource.__new__(PairSource)
        src.__dict__.update(self.__dict__)
        src.face_mask = fm
        src._levels = LRUCache(LEVEL_CACHE_BYTES)  # the levels follow the usable faces, which the mask changes
        return src
