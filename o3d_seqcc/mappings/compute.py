"""Pairwise mappings between views (paper section 3.1), filtered by :mod:`o3d_seqcc.visibility`.

A *pairwise mapping* is a pair of pixel coordinates, one in view ``a`` and one in view ``b``,
of the same surface point of the mesh. The paper uses the projections of the three vertices of
every face that is valid and unfiltered in both views (``mode="vertices"``); ``mode="dense"``
additionally samples points inside each face (sub-triangle centroids) whose number adapts to the
face's projected size (more observations for small overlaps). Both count mappings, so a count
(and the graph threshold ``t_npm``) depends on how finely the mesh is tessellated.

``mode="surface"`` (the default) samples the surface both views see at least at the photos'
resolution: the vertices of every shared face (as the paper) and, inside faces larger than
``sample_spacing``^2 px in the smaller of the two projections, about one point per
``sample_spacing``^2 px (sub-triangle centroids), and counts a pair by the area of that surface
in pixels
(:func:`~o3d_seqcc.mappings.counting.shared_area`), so the counts, the graph and ``t_npm`` (pixels) mean
the same on a 300-face and a 3M-face mesh of one scene.

Storage is lazy: :func:`compute_mappings` keeps the per-view sparse visibility records and builds
a pair's arrays when ``mappings.pairs[(a, b)]`` is read (a few milliseconds; the last
``cache_size`` pairs are cached). Counts are computed up front
(:func:`~o3d_seqcc.mappings.counting.shared_counts`: bit-packed AND + popcount, or a sparse product for
many views).
Mappings are written to and read from ``.npz`` files by :mod:`o3d_seqcc.io.mappings_npz`.

Pixel coordinates follow the package convention: x right, y down, pixel centres at integers.
"""

from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping

import numpy as np

from ..errors import InputError
from .pairs import LazyPairs, Pair, PairMapping, PairSource, norm_key

__all__ = [
    "DEFAULT_MODE",
    "MODES",
    "Mappings",
    "PairMapping",
    "compute_mappings",
]

logger = logging.getLogger(__name__)

#: mapping modes accepted by :func:`compute_mappings`
MODES = ("surface", "vertices", "dense")
#: the default mapping mode: :attr:`o3d_seqcc.correction.settings.CorrectionSettings.mappings` (the mode is
#: defined here, with :data:`MODES`, the stage before the correction; every entry point reads it from the settings)
DEFAULT_MODE = "surface"



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
        ``"surface"``, ``"vertices"`` or ``"dense"`` (or a free label for hand-built mappings).
    filter_stats : dict
        What each filter removed (see :func:`o3d_seqcc.visibility.compute_visibility`).
    visibility : Visibility or None
        The visibility the mappings were derived from (None when loaded from a file).
    counts : dict[(int, int), int]
        Number of mappings per pair (same keys as ``pairs``); computed when not given. In
        ``"surface"`` mode: the pair's shared surface in pixels (not its number of samples).
    n_views : int
        Number of views (from ``view_names`` when not given).
    image_sizes : tuple of (width, height), optional
        The photos' sizes (``t_npm="auto"``; from the visibility when not given).
    """

    pairs: Mapping[Pair, PairMapping]
    view_names: tuple[str, ...] = ()
    mode: str = "vertices"
    filter_stats: dict = field(default_factory=dict)
    visibility: Any = None
    counts: dict | None = None
    n_views: int | None = None
    image_sizes: tuple | None = None

    def __post_init__(self) -> None:
        pairs = self.pairs
        if not isinstance(pairs, LazyPairs):
            pairs = {}
            for key, pm in dict(self.pairs).items():
                a, b = norm_key(key)
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
        sizes = self.image_sizes
        if sizes is None:
            sizes = getattr(self.visibility, "image_sizes", None)
        if sizes is not None:
            sizes = tuple((int(w), int(h)) for w, h in sizes)
            if len(sizes) != n_views:
                raise ValueError(f"{len(sizes)} image sizes for {n_views} views")
        object.__setattr__(self, "image_sizes", sizes)

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
            image_sizes=self.image_sizes,
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
            a, b = norm_key(key)
            if a == b or min(a, b) < 0 or max(a, b) >= self.n_views:
                raise ValueError(f"invalid pair {key} for {self.n_views} views")
            k = (min(a, b), max(a, b))
            if k in self.counts:
                keep.add(k)
        counts = {k: n for k, n in self.counts.items() if k in keep}
        if isinstance(self.pairs, LazyPairs):
            return self._replace(LazyPairs(self.pairs.source, counts.keys()), counts)
        return self._replace({k: self.pairs[k] for k in sorted(keep)}, counts)

    def faces(self) -> np.ndarray:
        """Sorted unique face ids present in any pair."""
        if isinstance(self.pairs, LazyPairs):
            src = self.pairs.source
            seen = np.zeros(src.vis.n_faces, dtype=bool)
            for a, b in self.pairs:
                seen[src.faces(a, b)] = True
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
        if isinstance(self.pairs, LazyPairs):
            src = self.pairs.source
            F = src.vis.n_faces
            tmask = np.zeros(F, bool)
            tmask[test_faces] = True
            out = []
            for m in (~tmask, tmask):
                s = src.with_mask(m)
                counts = {k: n for k, n in s.counts().items() if k in self.counts}
                out.append(self._replace(LazyPairs(s, counts.keys()), counts))
            return out[0], out[1]
        fit, test = {}, {}
        for k, pm in self.pairs.items():
            is_test = np.isin(pm.face_ids, test_faces)
            fit[k] = pm.take(~is_test)
            test[k] = pm.take(is_test)
        fit = {k: v for k, v in fit.items() if v.n}
        test = {k: v for k, v in test.items() if v.n}

        def share(part: dict) -> dict:  # counts in the mappings' units (pixels for surface mappings)
            return {k: int(round(self.counts[k] * v.n / max(self.pairs[k].n, 1))) for k, v in part.items()}

        return self._replace(fit, share(fit)), self._replace(test, share(test))

    def materialize(self) -> "Mappings":
        """A copy whose ``pairs`` is a plain dict (builds every pair now)."""
        return self._replace({k: self.pairs[k] for k in self.pairs}, dict(self.counts))


# --------------------------------------------------------------------------------------------
# computation
# --------------------------------------------------------------------------------------------


def _max_usable_area(vis) -> np.ndarray:
    """(F,) float32: every face's largest projected area over the views where it is usable (0 if none)."""
    out = np.zeros(vis.n_faces, dtype=np.float32)
    _, faces, area, _ = vis.usable_entries()
    np.maximum.at(out, faces, area)
    return out


def compute_mappings(
    scene,
    *,
    mappings: str | None = None,
    visibility=None,
    sample_spacing: float = 3.0,
    dense_spacing: float = 3.0,
    dense_max_level: int = 6,
    cache_size: int = 8,
    mode: str | None = None,
    **filter_options: Any,
) -> Mappings:
    """Pairwise mappings of every pair of views (paper 3.1), after the filters of 3.2.

    Parameters
    ----------
    scene : Scene or None
        May be None when ``visibility`` is given.
    mappings : {"surface", "vertices", "dense"}, default :data:`DEFAULT_MODE` ("surface")
        The mapping mode (:attr:`o3d_seqcc.correction.settings.CorrectionSettings.mappings`, the
        command line's ``--mappings``). ``"surface"``: the vertices of every face usable in both views and points inside the
        larger ones, about one per ``sample_spacing``^2 pixels of the smaller projection; pairs
        counted by their shared surface in pixels (see the module docstring). ``"vertices"``: the projections of the 3
        vertices of every face usable in both views (the paper). ``"dense"``: the 3 vertices plus the centroids of the ``L**2`` sub-triangles
        of a level-``L`` subdivision of each such face, ``L = clip(ceil(sqrt(2 * A) /
        dense_spacing), 1, dense_max_level)`` where ``A`` is the face's largest projected area
        (px^2) over the views where it is usable; so dense is a superset of vertices mode with
        at least one more sample (the centroid) per face.
    visibility : Visibility, optional
        Precomputed :func:`~o3d_seqcc.visibility.compute_visibility` result (then
        ``filter_options`` must be empty).
    sample_spacing : float, default 3.0
        Surface mode: spacing in pixels (of the view where the face is smaller) of the samples
        inside faces larger than ``sample_spacing**2`` px, besides their vertices.
    dense_spacing : float, default 3.0
        Target spacing of dense samples in pixels (in the view where the face is largest).
    dense_max_level : int, default 6
        Cap on the subdivision level (at most 3 + 36 points per face).
    cache_size : int, default 8
        Number of built pairs kept in memory by the lazy ``pairs`` mapping.
    mode : str, optional
        Deprecated name of ``mappings`` (a ``DeprecationWarning``).
    **filter_options
        Passed to :func:`~o3d_seqcc.visibility.compute_visibility` (``mesh``, ``settings``, the
        fields of :class:`~o3d_seqcc.visibility.settings.VisibilitySettings`, ``n_jobs``, ...).

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

    Examples
    --------
    >>> import tempfile, o3d_seqcc as sc
    >>> room = sc.make_synthetic_scene(tempfile.mkdtemp() + '/room', n_views=3, width=96, height=72, seed=1,
    ...                                seen_only=True)
    >>> maps = sc.compute_mappings(room.scene)  # surface mappings by default
    >>> maps.mode, maps.total > 0
    ('surface', True)
    """
    from ..visibility.compute import compute_visibility

    if mode is not None:
        warnings.warn("compute_mappings(mode=...) is deprecated: the option is called mappings= (as in "
                      "pipeline.run, correct and --mappings)", DeprecationWarning, stacklevel=2)
        if mappings is not None and mappings != mode:
            raise InputError(f"compute_mappings: mappings={mappings!r} and its old name mode={mode!r} disagree")
        mappings = mode
    mode = DEFAULT_MODE if mappings is None else mappings
    if mode not in MODES:
        raise InputError(f"unknown mapping mode {mode!r}; valid: {', '.join(MODES)}")
    if visibility is None:
        visibility = compute_visibility(scene, **filter_options)
    elif filter_options:
        raise TypeError(f"filter options {sorted(filter_options)} cannot be combined with a precomputed visibility")
    elif scene is not None and visibility.n_views != len(scene.views):
        raise InputError(
            f"the visibility is for {visibility.n_views} views but the scene has {len(scene.views)}; recompute it"
        )
    level = None
    if mode == "surface" and not sample_spacing > 0:
        raise ValueError(f"sample_spacing must be > 0, got {sample_spacing}")
    if mode == "dense":
        if dense_spacing <= 0:
            raise ValueError(f"dense_spacing must be > 0, got {dense_spacing}")
        max_area = _max_usable_area(visibility)
        level = np.clip(np.ceil(np.sqrt(2.0 * max_area.astype(np.float64)) / dense_spacing), 1, int(dense_max_level))
        level = level.astype(np.int64)
    src = PairSource(visibility, mode, level, None, spacing=sample_spacing)
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
        "mappings (%s): %d of %d pairs overlap, %d %s in total", mode, len(counts), n_pairs, sum(counts.values()),
        "px of shared surface" if mode == "surface" else "mappings",
    )
    return Mappings(
        pairs=LazyPairs(src, counts.keys(), cache_size=cache_size),
        view_names=names,
        mode=mode,
        filter_stats=visibility.stats,
        visibility=visibility,
        counts=counts,
        n_views=len(names),
        image_sizes=getattr(visibility, "image_sizes", None)
        or (tuple((v.width, v.height) for v in scene.views) if scene is not None else None),
    )
