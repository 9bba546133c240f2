"""Pairwise mappings between views (paper section 3.1), filtered by :mod:`o3d_seqcc.visibility`.

A *pairwise mapping* is a pair of pixel coordinates, one in view ``a`` and one in view ``b``,
of the same surface point of the mesh. The paper uses the projections of the three vertices of
every face that is valid and unfiltered in both views (``mode="vertices"``); ``mode="dense"``
additionally samples points inside each face (sub-triangle centroids) whose number adapts to the
face's projected size (more observations for small overlaps).

Storage is lazy: :func:`compute_mappings` keeps the per-view usable-face masks and builds a
pair's arrays when ``mappings.pairs[(a, b)]`` is read (a few milliseconds; the last
``cache_size`` pairs are cached). Counts are computed up front (bit-packed AND + popcount).

Pixel coordinates follow the package convention: x right, y down, pixel centres at integers.
"""

from __future__ import annotations

import io
import json
import logging
import os
import threading
from collections import OrderedDict
from collections.abc import Mapping as _MappingABC
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Iterator, Mapping

import numpy as np

from ._io import atomic_write_bytes, to_jsonable
from .errors import InputError

__all__ = [
    "MODES",
    "Mappings",
    "PairMapping",
    "compute_mappings",
    "load_mappings",
    "plot_pair",
    "sample_colors",
]

logger = logging.getLogger(__name__)

#: mapping modes accepted by :func:`compute_mappings`
MODES = ("vertices", "dense")

Pair = tuple[int, int]


# --------------------------------------------------------------------------------------------
# colour sampling
# --------------------------------------------------------------------------------------------


def sample_colors(image: np.ndarray, uv: np.ndarray, *, interpolation: str = "bilinear") -> np.ndarray:
    """Sample an image at sub-pixel positions.

    Parameters
    ----------
    image : (H, W, C) or (H, W) array
        uint8, uint16 or float image (C is usually 3).
    uv : (n, 2) array
        Pixel coordinates, x right, y down, pixel centres at integers. Positions outside
        ``[0, W-1] x [0, H-1]`` (e.g. in the outer half pixel) are clamped to the border.
    interpolation : {"bilinear", "nearest"}, default "bilinear"
        Bilinear interpolation of the four surrounding pixel centres, or the pixel whose area
        contains the point (``floor(x + 0.5)``).

    Returns
    -------
    (n, C) float64 (or (n,) for a 2-D image)
        Colours in the image's own units (0-255 for uint8, 0-65535 for uint16).

    Raises
    ------
    ValueError
        Unknown interpolation, malformed or non-finite ``uv``.
    """
    img = np.asarray(image)
    if img.ndim not in (2, 3):
        raise ValueError(f"image must be (H, W) or (H, W, C), got shape {img.shape}")
    uv = np.asarray(uv, dtype=np.float64)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise ValueError(f"uv must have shape (n, 2), got {uv.shape}")
    if not np.all(np.isfinite(uv)):
        raise ValueError("uv contains NaN/inf")
    H, W = img.shape[:2]
    x = np.clip(uv[:, 0], 0.0, W - 1.0)
    y = np.clip(uv[:, 1], 0.0, H - 1.0)
    if interpolation == "nearest":
        xi = np.minimum(np.floor(x + 0.5).astype(np.intp), W - 1)
        yi = np.minimum(np.floor(y + 0.5).astype(np.intp), H - 1)
        return img[yi, xi].astype(np.float64)
    if interpolation != "bilinear":
        raise ValueError(f"unknown interpolation {interpolation!r}; valid: 'bilinear', 'nearest'")
    x0 = np.floor(x).astype(np.intp)
    y0 = np.floor(y).astype(np.intp)
    x1 = np.minimum(x0 + 1, W - 1)
    y1 = np.minimum(y0 + 1, H - 1)
    fx = x - x0
    fy = y - y0
    if img.ndim == 3:
        fx = fx[:, None]
        fy = fy[:, None]
    top = img[y0, x0].astype(np.float64) * (1.0 - fx) + img[y0, x1].astype(np.float64) * fx
    bot = img[y1, x0].astype(np.float64) * (1.0 - fx) + img[y1, x1].astype(np.float64) * fx
    return top * (1.0 - fy) + bot * fy


# --------------------------------------------------------------------------------------------
# data structures
# --------------------------------------------------------------------------------------------


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


def _norm_key(key: Any) -> Pair:
    try:
        a, b = key
        return int(a), int(b)
    except (TypeError, ValueError):
        raise KeyError(key) from None


class _LazyPairs(_MappingABC):
    """Read-only ``{(a, b): PairMapping}`` whose values are built on access (LRU-cached)."""

    def __init__(self, source: "_PairSource", keys: Iterable[Pair], *, cache_size: int = 8) -> None:
        self._source = source
        self._keys = sorted(_norm_key(k) for k in keys)
        self._keyset = set(self._keys)
        self._cache: OrderedDict[Pair, PairMapping] = OrderedDict()
        self._cache_size = int(cache_size)
        self._lock = threading.Lock()

    def __getitem__(self, key: Any) -> PairMapping:
        k = _norm_key(key)
        if k not in self._keyset:
            raise KeyError(key)
        with self._lock:
            pm = self._cache.get(k)
            if pm is not None:
                self._cache.move_to_end(k)
                return pm
        pm = self._source.build(*k)
        if self._cache_size > 0:
            with self._lock:
                self._cache[k] = pm
                while len(self._cache) > self._cache_size:
                    self._cache.popitem(last=False)
        return pm

    def __contains__(self, key: object) -> bool:
        try:
            return _norm_key(key) in self._keyset
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


def _bary_table(max_level: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Dense sampling patterns for levels 1..max_level, concatenated.

    Level L has the 3 vertices (first, in face order, as in ``"vertices"`` mode) followed by the
    centroids of the L^2 sub-triangles of the level-L subdivision of the face (strictly inside
    the face, so no two faces share a dense sample): 3 + L^2 points. Returns
    (table (T, 3) float64 barycentric weights, start (max_level+1,), count (max_level+1,)).
    """
    rows = []
    start = np.zeros(max_level + 1, dtype=np.int64)
    count = np.zeros(max_level + 1, dtype=np.int64)
    off = 0
    for L in range(1, max_level + 1):
        i, j = np.meshgrid(np.arange(L), np.arange(L), indexing="ij")
        up = (i + j) <= L - 1
        down = (i + j) <= L - 2
        b1 = np.concatenate([i[up] + 1 / 3, i[down] + 2 / 3]) / L
        b2 = np.concatenate([j[up] + 1 / 3, j[down] + 2 / 3]) / L
        w = np.concatenate([np.eye(3), np.stack([1.0 - b1 - b2, b1, b2], axis=1)])
        start[L] = off
        count[L] = len(w)
        rows.append(w)
        off += len(w)
    return np.concatenate(rows), start, count


def _shared_counts(U: np.ndarray) -> np.ndarray:
    """(V, V) int64 number of columns where both rows of the (V, F) bool matrix are True."""
    V, F = U.shape
    P = np.packbits(U, axis=1)
    pad = (-P.shape[1]) % 8
    if pad:
        P = np.concatenate([P, np.zeros((V, pad), np.uint8)], axis=1)
    P = np.ascontiguousarray(P).view(np.uint64)
    C = np.zeros((V, V), dtype=np.int64)
    for a in range(V):
        C[a, a:] = np.bitwise_count(P[a] & P[a:]).sum(axis=1, dtype=np.int64)
    return np.triu(C) + np.triu(C, 1).T


class _PairSource:
    """Builds the mappings of one pair from a :class:`~o3d_seqcc.visibility.Visibility`."""

    def __init__(self, vis, mode: str, level: np.ndarray | None, face_mask: np.ndarray | None) -> None:
        self.vis = vis
        self.mode = mode
        self.level = level  # (F,) int per face (dense mode)
        self.face_mask = face_mask  # (F,) bool or None
        if mode == "dense":
            self.table, self.start, self.count = _bary_table(int(level.max()) if len(level) else 1)
        else:
            self.count = np.array([0, 3])

    def usable(self) -> np.ndarray:
        u = self.vis.usable
        return u if self.face_mask is None else (u & self.face_mask[None, :])

    def per_face(self) -> np.ndarray:
        F = self.vis.n_faces
        if self.mode == "vertices":
            return np.full(F, 3, dtype=np.int64)
        return self.count[self.level]

    def counts(self) -> dict[Pair, int]:
        U = self.usable()
        if self.mode == "vertices":
            C = 3 * _shared_counts(U)
        else:
            C = np.zeros((U.shape[0], U.shape[0]), dtype=np.int64)
            for L in np.unique(self.level):
                C += int(self.count[L]) * _shared_counts(U & (self.level == L)[None, :])
        a, b = np.triu_indices(U.shape[0], k=1)
        c = C[a, b]
        return {(int(i), int(j)): int(n) for i, j, n in zip(a, b, c) if n > 0}

    def faces(self, a: int, b: int) -> np.ndarray:
        both = self.vis.usable[a] & self.vis.usable[b]
        if self.face_mask is not None:
            both &= self.face_mask
        return np.flatnonzero(both)

    def build(self, a: int, b: int) -> PairMapping:
        vis = self.vis
        k = self.faces(a, b)
        tri = vis.mesh.faces[k]  # (m, 3)
        if self.mode == "vertices":
            uv_a = vis.uv[a][tri].reshape(-1, 2)
            uv_b = vis.uv[b][tri].reshape(-1, 2)
            return PairMapping(a, b, uv_a, uv_b, np.repeat(k, 3))
        # dense: faces grouped by level; per level the samples are a fixed barycentric pattern
        lev = self.level[k]
        order = np.argsort(lev, kind="stable")
        k, tri, lev = k[order], tri[order], lev[order]
        bounds = np.flatnonzero(np.diff(lev)) + 1
        starts = np.concatenate([[0], bounds])
        ends = np.concatenate([bounds, [len(k)]])
        uv_out = {a: [], b: []}
        fids, ws = [], []
        for s0, s1 in zip(starts, ends):
            if s1 <= s0:
                continue
            L = int(lev[s0])
            Wl = self.table[self.start[L] : self.start[L] + self.count[L]]  # (p, 3)
            t = tri[s0:s1]
            for v in (a, b):
                z = vis.depth[v][t].astype(np.float64)  # (m, 3)
                uvz = vis.uv[v][t].astype(np.float64) * z[:, :, None]  # (m, 3, 2)
                num = np.zeros((len(t), len(Wl), 2))
                den = np.zeros((len(t), len(Wl)))
                for j in range(3):
                    num += Wl[None, :, j, None] * uvz[:, None, j, :]
                    den += Wl[None, :, j] * z[:, None, j]
                # perspective-correct: projection of sum(w_i X_i) = sum(w_i z_i uv_i) / sum(w_i z_i)
                uv_out[v].append((num / den[:, :, None]).reshape(-1, 2))
            fids.append(np.repeat(k[s0:s1], len(Wl)))
            ws.append(np.broadcast_to(Wl.astype(np.float32), (s1 - s0,) + Wl.shape).reshape(-1, 3))
        if not fids:
            e2 = np.zeros((0, 2))
            return PairMapping(a, b, e2, e2, np.zeros(0, np.int64), np.zeros((0, 3), np.float32))
        return PairMapping(
            a, b, np.concatenate(uv_out[a]), np.concatenate(uv_out[b]), np.concatenate(fids), np.concatenate(ws)
        )

    def with_mask(self, face_mask: np.ndarray) -> "_PairSource":
        fm = face_mask if self.face_mask is None else (self.face_mask & face_mask)
        src = _PairSource.__new__(_PairSource)
        src.__dict__.update(self.__dict__)
        src.face_mask = fm
        return src


@dataclass(frozen=True, eq=False)
class Mappings:
    """Pairwise mappings of a scene.

    Attributes
    ----------
    pairs : Mapping[(int, int), PairMapping]
        Keyed ``(a, b)`` with ``a < b``; only pairs with at least one mapping are present.
        From :func:`compute_mappings` this is a lazy read-only mapping (values built on access).
    view_names : tuple of str
    mode : str
        ``"vertices"`` or ``"dense"`` (or a free label for hand-built mappings).
    filter_stats : dict
        What each filter removed (see :func:`o3d_seqcc.visibility.compute_visibility`).
    visibility : Visibility or None
        The visibility the mappings were derived from (None when loaded from a file).
    counts : dict[(int, int), int]
        Number of mappings per pair (same keys as ``pairs``); computed when not given.
    n_views : int
        Number of views (from ``view_names`` when not given).
    """

    pairs: Mapping[Pair, PairMapping]
    view_names: tuple[str, ...] = ()
    mode: str = "vertices"
    filter_stats: dict = field(default_factory=dict)
    visibility: Any = None
    counts: dict | None = None
    n_views: int | None = None

    def __post_init__(self) -> None:
        pairs = self.pairs
        if not isinstance(pairs, _LazyPairs):
            pairs = {}
            for key, pm in dict(self.pairs).items():
                a, b = _norm_key(key)
                if a == b:
                    raise ValueError(f"pair {key}: a view cannot be paired with itself")
                if a > b:
                    a, b = b, a
                    pm = pm.swapped() if (pm.a, pm.b) != (a, b) else pm
                if pm.n > 0:
                    pairs[(a, b)] = pm
            pairs = dict(sorted(pairs.items()))
            object.__setattr__(self, "pairs", pairs)
        names = tuple(str(n) for n in self.view_names)
        n_views = self.n_views
        if n_views is None:
            n_views = len(names) if names else (max((b for _, b in pairs), default=-1) + 1)
        n_views = int(n_views)
        if not names:
            names = tuple(str(i) for i in range(n_views))
        if len(names) != n_views:
            raise ValueError(f"{len(names)} view names for {n_views} views")
        if any(b >= n_views or a < 0 for a, b in pairs):
            raise ValueError(f"pair indices out of range for {n_views} views")
        object.__setattr__(self, "view_names", names)
        object.__setattr__(self, "n_views", n_views)
        if self.counts is None:
            object.__setattr__(self, "counts", {k: pm.n for k, pm in pairs.items()})
        else:
            object.__setattr__(self, "counts", dict(self.counts))

    # ---------------------------------------------------------------------------------------

    @property
    def total(self) -> int:
        """Total number of mappings over all pairs."""
        return int(sum(self.counts.values()))

    def count(self, a: int, b: int) -> int:
        """Number of mappings of the pair (either order; 0 when absent)."""
        a, b = (a, b) if a < b else (b, a)
        return int(self.counts.get((a, b), 0))

    def pair(self, a: int, b: int) -> PairMapping:
        """The mappings of a pair oriented as asked (``uv_a`` in view ``a``); empty if none."""
        if a == b:
            raise ValueError("a view cannot be paired with itself")
        lo, hi = (a, b) if a < b else (b, a)
        pm = self.pairs.get((lo, hi))
        if pm is None:
            e2 = np.zeros((0, 2))
            pm = PairMapping(lo, hi, e2, e2, np.zeros(0, np.int64))
        return pm if a < b else pm.swapped()

    def world_points(self, a: int, b: int) -> np.ndarray:
        """(n, 3) float64 world points of the pair's mappings (needs ``visibility`` and weights)."""
        if self.visibility is None:
            raise ValueError("world_points needs the mesh: these mappings have no visibility attached")
        pm = self.pair(a, b)
        mesh = self.visibility.mesh
        if pm.weights is None:
            if self.mode != "vertices":
                raise ValueError("world_points needs barycentric weights, absent in these mappings")
            # vertices mode: the mappings are the face vertices in order, 3 per face
            corner = np.tile(np.arange(3), pm.n // 3 + 1)[: pm.n]
            return mesh.vertices[mesh.faces[pm.face_ids, corner]]
        tri = mesh.vertices[mesh.faces[pm.face_ids]]
        return (pm.weights.astype(np.float64)[:, :, None] * tri).sum(1)

    def _replace(self, pairs: Mapping[Pair, PairMapping], counts: dict) -> "Mappings":
        return Mappings(
            pairs=pairs,
            view_names=self.view_names,
            mode=self.mode,
            filter_stats=self.filter_stats,
            visibility=self.visibility,
            counts=counts,
            n_views=self.n_views,
        )

    def subset(self, pairs: Iterable[Pair]) -> "Mappings":
        """Only the given pairs (either order accepted; pairs without mappings are skipped).

        Raises
        ------
        ValueError
            A pair refers to a view index outside ``0..n_views-1`` or pairs a view with itself.
        """
        keep = set()
        for key in pairs:
            a, b = _norm_key(key)
            if a == b or min(a, b) < 0 or max(a, b) >= self.n_views:
                raise ValueError(f"invalid pair {key} for {self.n_views} views")
            k = (min(a, b), max(a, b))
            if k in self.counts:
                keep.add(k)
        counts = {k: n for k, n in self.counts.items() if k in keep}
        if isinstance(self.pairs, _LazyPairs):
            return self._replace(_LazyPairs(self.pairs._source, counts.keys()), counts)
        return self._replace({k: self.pairs[k] for k in sorted(keep)}, counts)

    def faces(self) -> np.ndarray:
        """Sorted unique face ids present in any pair."""
        if isinstance(self.pairs, _LazyPairs):
            src = self.pairs._source
            U = src.usable()
            seen = np.zeros(U.shape[1], dtype=bool)
            for a, b in self.pairs:
                seen |= U[a] & U[b]
            return np.flatnonzero(seen)
        if not self.pairs:
            return np.zeros(0, np.int64)
        return np.unique(np.concatenate([self.pairs[k].face_ids for k in self.pairs]))

    def split(self, holdout: float, *, seed: int = 0) -> tuple["Mappings", "Mappings"]:
        """Split the mappings by face: a random ``holdout`` fraction of the faces goes to the test set.

        Parameters
        ----------
        holdout : float in (0, 1)
            Fraction of the faces (with at least one mapping) held out.
        seed : int, default 0

        Returns
        -------
        (fit, test) : tuple of Mappings
            Disjoint in faces; together they hold every mapping.
        """
        holdout = float(holdout)
        if not 0.0 < holdout < 1.0:
            raise ValueError(f"holdout must be in (0, 1), got {holdout}")
        faces = self.faces()
        rng = np.random.default_rng(seed)
        n_test = int(round(holdout * len(faces)))
        test_faces = np.sort(rng.permutation(faces)[:n_test])
        if isinstance(self.pairs, _LazyPairs):
            src = self.pairs._source
            F = src.vis.n_faces
            tmask = np.zeros(F, bool)
            tmask[test_faces] = True
            out = []
            for m in (~tmask, tmask):
                s = src.with_mask(m)
                counts = {k: n for k, n in s.counts().items() if k in self.counts}
                out.append(self._replace(_LazyPairs(s, counts.keys()), counts))
            return out[0], out[1]
        fit, test = {}, {}
        for k, pm in self.pairs.items():
            is_test = np.isin(pm.face_ids, test_faces)
            fit[k] = pm.take(~is_test)
            test[k] = pm.take(is_test)
        fit = {k: v for k, v in fit.items() if v.n}
        test = {k: v for k, v in test.items() if v.n}
        return (
            self._replace(fit, {k: v.n for k, v in fit.items()}),
            self._replace(test, {k: v.n for k, v in test.items()}),
        )

    def materialize(self) -> "Mappings":
        """A copy whose ``pairs`` is a plain dict (builds every pair now)."""
        return self._replace({k: self.pairs[k] for k in self.pairs}, dict(self.counts))

    # ---------------------------------------------------------------------------------------

    def save(self, path: str | os.PathLike, *, format: str = "auto", dtype: str = "float32") -> Path:
        """Write the mappings to an ``.npz`` file atomically; read it back with :func:`load_mappings`.

        Parameters
        ----------
        path : path-like
        format : {"auto", "compact", "arrays"}, default "auto"
            ``"arrays"``: every pair's arrays concatenated: ``pairs`` (P, 2) int32, ``offsets``
            (P+1,) int64, ``counts`` (P,), ``uv_a`` / ``uv_b`` (M, 2) in ``dtype``, ``face_ids``
            (M,) int64 (slice ``offsets[i]:offsets[i+1]`` is pair ``pairs[i]``), ``weights``
            (M, 3) float32 when every pair has them. ``"compact"`` (mappings from
            :func:`compute_mappings` only): what the pairs are built from: per-vertex ``uv``
            (V, N, 2) float32 and ``depth`` (V, N), bit-packed ``usable`` (V, F) faces, the mesh
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
        lazy = isinstance(self.pairs, _LazyPairs)
        if format == "compact" and not lazy:
            raise ValueError("the compact layout needs mappings from compute_mappings (lazy pairs)")
        keys = list(self.pairs.keys())
        data: dict[str, np.ndarray] = {
            "format": np.array("o3d_seqcc.mappings/1"),
            "view_names": np.array(self.view_names, dtype=str),
            "mode": np.array(self.mode),
            "pairs": np.array(keys, dtype=np.int32).reshape(-1, 2),
            "counts": np.array([self.counts[k] for k in keys], dtype=np.int64),
            "filter_stats": np.array(json.dumps(to_jsonable(self.filter_stats))),
        }
        if lazy and format != "arrays":
            src = self.pairs._source
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
            if src.face_mask is not None:
                data["face_mask"] = np.packbits(src.face_mask)
        else:
            pms = [self.pairs[k] for k in keys]
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


class _StoredVisibility:
    """The parts of a Visibility that pair building needs (compact mappings files)."""

    def __init__(self, uv, depth, usable, vertices, faces) -> None:
        from .scene import Mesh

        self.uv = uv
        self.depth = depth
        self.usable = usable
        self.mesh = Mesh(vertices=vertices, faces=faces, vertex_normals=np.zeros_like(vertices))

    @property
    def n_views(self) -> int:
        return int(self.usable.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.usable.shape[1])


def load_mappings(path: str | os.PathLike) -> Mappings:
    """Read mappings written by :meth:`Mappings.save` (``visibility`` is None).

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
        if layout == "compact":
            F = int(z["n_faces"])
            usable = np.unpackbits(z["usable"], axis=1, count=F).astype(bool)
            vis = _StoredVisibility(z["uv"], z["depth"], usable, z["vertices"], z["faces"])
            level = z["level"].astype(np.int64) if "level" in files else None
            face_mask = np.unpackbits(z["face_mask"], count=F).astype(bool) if "face_mask" in files else None
            src = _PairSource(vis, mode, level, face_mask)
            return Mappings(
                pairs=_LazyPairs(src, keys), view_names=names, mode=mode, filter_stats=stats, counts=counts
            )
        off = z["offsets"]
        uv_a, uv_b, fid = z["uv_a"].astype(np.float64), z["uv_b"].astype(np.float64), z["face_ids"]
        w = z["weights"] if "weights" in files else None
        pairs = {}
        for i, (a, b) in enumerate(keys):
            s = slice(int(off[i]), int(off[i + 1]))
            pairs[(a, b)] = PairMapping(a, b, uv_a[s], uv_b[s], fid[s], None if w is None else w[s])
    return Mappings(pairs=pairs, view_names=names, mode=mode, filter_stats=stats, counts=counts)


# --------------------------------------------------------------------------------------------
# computation
# --------------------------------------------------------------------------------------------


def compute_mappings(
    scene,
    *,
    mode: str = "vertices",
    visibility=None,
    dense_spacing: float = 3.0,
    dense_max_level: int = 6,
    cache_size: int = 8,
    **filter_options: Any,
) -> Mappings:
    """Pairwise mappings of every pair of views (paper 3.1), after the filters of 3.2.

    Parameters
    ----------
    scene : Scene or None
        May be None when ``visibility`` is given.
    mode : {"vertices", "dense"}, default "vertices"
        ``"vertices"``: the projections of the 3 vertices of every face usable in both views
        (the paper). ``"dense"``: the 3 vertices plus the centroids of the ``L**2`` sub-triangles
        of a level-``L`` subdivision of each such face, ``L = clip(ceil(sqrt(2 * A) /
        dense_spacing), 1, dense_max_level)`` where ``A`` is the face's largest projected area
        (px^2) over the views where it is usable; so dense is a superset of vertices mode with
        at least one more sample (the centroid) per face.
    visibility : Visibility, optional
        Precomputed :func:`~o3d_seqcc.visibility.compute_visibility` result (then
        ``filter_options`` must be empty).
    dense_spacing : float, default 3.0
        Target spacing of dense samples in pixels (in the view where the face is largest).
    dense_max_level : int, default 6
        Cap on the subdivision level (at most 3 + 36 points per face).
    cache_size : int, default 8
        Number of built pairs kept in memory by the lazy ``pairs`` mapping.
    **filter_options
        Passed to :func:`~o3d_seqcc.visibility.compute_visibility` (``mesh``, ``occlusion_tol``,
        ``depth_tol``, ``max_angle``, ``n_jobs``, ...).

    Returns
    -------
    Mappings
        ``filter_stats`` is ``visibility.stats``.

    Raises
    ------
    ValueError
        Unknown mode (lists the valid ones).
    TypeError
        Unknown filter option, or filter options together with ``visibility``.
    InputError
        No pair of views shares a usable face.
    """
    from .visibility import compute_visibility

    if mode not in MODES:
        raise ValueError(f"unknown mapping mode {mode!r}; valid: {', '.join(MODES)}")
    if visibility is None:
        visibility = compute_visibility(scene, **filter_options)
    elif filter_options:
        raise TypeError(f"filter options {sorted(filter_options)} cannot be combined with a precomputed visibility")
    elif scene is not None and visibility.n_views != len(scene.views):
        raise InputError(
            f"the visibility is for {visibility.n_views} views but the scene has {len(scene.views)}; recompute it"
        )
    level = None
    if mode == "dense":
        if dense_spacing <= 0:
            raise ValueError(f"dense_spacing must be > 0, got {dense_spacing}")
        max_area = np.where(visibility.usable, visibility.area, 0.0).max(axis=0) if visibility.n_views else None
        level = np.clip(np.ceil(np.sqrt(2.0 * max_area.astype(np.float64)) / dense_spacing), 1, int(dense_max_level))
        level = level.astype(np.int64)
    src = _PairSource(visibility, mode, level, None)
    counts = src.counts()
    names = tuple(visibility.view_names) or tuple(v.name for v in scene.views)
    if len(names) != visibility.n_views:
        names = tuple(str(i) for i in range(visibility.n_views))
    if not counts:
        raise InputError(
            "no overlap: no pair of views shares a face that is visible and passes the filters in both "
            f"({len(names)} views); check the camera poses against the mesh, or relax the filters "
            "(max_angle, depth_tol, occlusion_tol)"
        )
    n_pairs = len(names) * (len(names) - 1) // 2
    logger.info(
        "mappings (%s): %d of %d pairs overlap, %d mappings in total", mode, len(counts), n_pairs, sum(counts.values())
    )
    return Mappings(
        pairs=_LazyPairs(src, counts.keys(), cache_size=cache_size),
        view_names=names,
        mode=mode,
        filter_stats=visibility.stats,
        visibility=visibility,
        counts=counts,
        n_views=len(names),
    )


# --------------------------------------------------------------------------------------------
# figure (paper Figures 2-3)
# --------------------------------------------------------------------------------------------


def _stage_pairs(mappings: Mappings, a: int, b: int) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(title, uv_a, uv_b) of the vertex mappings of a pair after each filter stage (Figure 3)."""
    vis = mappings.visibility
    titles = {
        "valid": "no filter",
        "+occlusion": "+ z-buffering",
        "+depth": "+ depth consistency",
        "+oblique": "+ camera viewpoint (final)",
    }
    out = []
    faces = vis.mesh.faces
    for key, m in vis.stage_masks().items():
        k = np.flatnonzero(m[a] & m[b])
        tri = faces[k]
        out.append((titles[key], vis.uv[a][tri].reshape(-1, 2), vis.uv[b][tri].reshape(-1, 2)))
    return out


def _position_colors(uv: np.ndarray, width: int, height: int) -> np.ndarray:
    """(n, 3) RGB in [0, 1]: hue from x, value from y (saturated, visible on photos)."""
    from matplotlib.colors import hsv_to_rgb

    h = np.clip(uv[:, 0] / max(width - 1, 1), 0, 1) * 0.85
    v = 1.0 - 0.45 * np.clip(uv[:, 1] / max(height - 1, 1), 0, 1)
    return hsv_to_rgb(np.stack([h, np.ones_like(h), v], axis=1))


def plot_pair(
    scene,
    mappings: Mappings,
    a: int | str,
    b: int | str,
    path: str | os.PathLike,
    *,
    stages: bool = True,
    max_points: int = 20000,
    marker_size: float | None = None,
    image_alpha: float = 0.5,
    seed: int = 0,
    images: tuple[np.ndarray, np.ndarray] | None = None,
) -> Path:
    """Figure of a pair's mappings like the paper's Figures 2-3, written atomically as PNG.

    Both images side by side with the mappings drawn as points; corresponding points have the
    same colour (a 2-D colour map of the position in view ``a``: the hue changes from left to
    right, the brightness from top to bottom). With ``stages`` and a visibility attached, four rows show the vertex mappings with
    no filter, + z-buffering, + depth consistency and + camera viewpoint (Figure 3 a-h);
    otherwise one row shows the mappings themselves.

    Parameters
    ----------
    scene : Scene
    mappings : Mappings
    a, b : int or str
        View indices or names.
    path : path-like
        Output PNG.
    stages : bool, default True
    max_points : int, default 20000
        Random subset drawn per row (seeded) when a row has more mappings.
    marker_size : float, optional
        Marker area in points^2; default ``4 * max(1, 640 / width)`` (bigger for small images).
    image_alpha : float, default 0.5
        Opacity of the photos (dimmed so that the points stand out).
    seed : int, default 0
    images : pair of arrays, optional
        Images to draw instead of the views' files (e.g. corrected images).

    Returns
    -------
    pathlib.Path
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    ia, ib = scene.index(a), scene.index(b)
    if ia == ib:
        raise ValueError("plot_pair needs two different views")
    va, vb = scene.views[ia], scene.views[ib]
    if images is None:
        images = (va.load_image(), vb.load_image())
    imgs = []
    for im in images:
        im = np.asarray(im)
        if im.dtype == np.uint16:
            im = (im / 65535.0).astype(np.float32)
        elif im.dtype != np.uint8:
            im = np.clip(im, 0, 1)
        imgs.append(im)
    if stages and mappings.visibility is not None:
        rows = _stage_pairs(mappings, ia, ib) if ia < ib else [
            (t, ub, ua) for t, ua, ub in _stage_pairs(mappings, ib, ia)
        ]
    else:
        pm = mappings.pair(ia, ib)
        rows = [(f"{mappings.mode} mappings", pm.uv_a, pm.uv_b)]
    rng = np.random.default_rng(seed)
    if marker_size is None:
        marker_size = 4.0 * max(1.0, 640.0 / max(va.width, vb.width))
    aspect = max(va.height / va.width, vb.height / vb.width)
    fig = Figure(figsize=(12, 12 * aspect * len(rows) / 2 + 0.6 * len(rows)), dpi=100)
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(rows), 2, squeeze=False)
    for r, (title, ua, ub) in enumerate(rows):
        n = len(ua)
        sel = rng.choice(n, max_points, replace=False) if n > max_points else np.arange(n)
        col = _position_colors(ua[sel], va.width, va.height)
        for c, (ax, img, uv, view) in enumerate(zip(axes[r], imgs, (ua, ub), (va, vb))):
            ax.imshow(img, interpolation="nearest", alpha=image_alpha)
            ax.scatter(uv[sel, 0], uv[sel, 1], s=marker_size, c=col, marker=".", linewidths=0)
            ax.set_xlim(-0.5, view.width - 0.5)
            ax.set_ylim(view.height - 0.5, -0.5)
            ax.set_xticks([])
            ax.set_yticks([])
            letter = "abcdefghijklmnop"[2 * r + c]
            ax.set_title(f"({letter}) {view.name}: {title}, {n} mappings", fontsize=9)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return atomic_write_bytes(path, buf.getvalue())
