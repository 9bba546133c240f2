"""Colour-correction weighted graph and Dijkstra correction paths (paper sections 3.3, 3.4).

Nodes are view indices ``0 .. n_views - 1``; an undirected edge joins two views whose number of
filtered pairwise mappings ``n(M_ik)`` reaches the threshold ``t_npm``. The edge weight is

    w_ik = 1 - n(M_ik) / sum_{all pairs} n(M)

where the sum runs over **all** pairwise mapping sets (every pair with a count, kept or not), as
in the paper's equation; so weights are in [0, 1) and a pair holding many mappings is cheap to
cross. Dijkstra's algorithm then gives each view the path to the reference with the highest sum
of mappings (lowest total cost).

``t_npm`` and its units
-----------------------
In the default ``"surface"`` mappings a pair's count is the area of the surface both views see,
in pixels of the view where it is smaller (:func:`o3d_seqcc.mappings.counting.shared_area`): the same on a
300-face and a 3M-face mesh of one scene. ``t_npm`` is then a number of pixels, and its default
``"auto"`` is :data:`AUTO_T_NPM_FRACTION` (1 %) of the median photo's pixels (3,072 px for
640 x 480 photos; on Fountain's 16k-face mesh the paper's 400 vertex mappings are 2,600-4,400 px
of shared surface, and 514 of its 528 pairs reach 3,072 px where 511 reach 400 vertex mappings).
:func:`resolve_t_npm` turns ``t_npm`` into the threshold in the mappings' units.

The paper's ``t_npm = 400`` counts *vertex* mappings (3 per face seen by both views, so about
133 shared faces). Dense (per-pixel) mappings produce roughly (projected face area in px) mappings
per face instead of 3, so the same overlap gives a much larger count. :func:`scale_t_npm` converts
a threshold given in vertex-mapping units into the units of the mappings at hand: for dense
mappings it multiplies ``t_npm`` by the mean number of mappings per (shared face x 3 vertices),
i.e. the threshold keeps meaning "about t_npm / 3 shared faces". :func:`o3d_seqcc.correction.correct`
applies it automatically, so with vertex and dense mappings ``t_npm`` is given in vertex-mapping
units (``"auto"``: the paper's 400).
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any, Mapping

import networkx as nx
import numpy as np

from ..errors import InputError

__all__ = ["AUTO_T_NPM_FRACTION", "PAPER_T_NPM", "WEIGHTS", "build_graph", "check_t_npm", "choose_reference",
           "correction_paths", "graph_edges", "mappings_summary", "resolve_t_npm", "scale_t_npm", "t_npm_units"]

if TYPE_CHECKING:
    from ..mappings.compute import Mappings

logger = logging.getLogger(__name__)


#: edge weight formulas of :func:`build_graph`
WEIGHTS = ("paper", "log")
#: ``t_npm="auto"`` with surface mappings: this fraction of the median photo's pixels
AUTO_T_NPM_FRACTION = 0.01
#: the paper's threshold in vertex mappings (``t_npm="auto"`` with vertex and dense mappings)
PAPER_T_NPM = 400


def check_t_npm(t_npm) -> None:
    """Raise ``InputError`` unless ``t_npm`` is ``"auto"`` or a positive integer."""
    if isinstance(t_npm, str) and t_npm == "auto":
        return
    if isinstance(t_npm, bool) or not isinstance(t_npm, (int, np.integer)) or t_npm < 1:
        raise InputError(f"t_npm must be 'auto' or a positive integer (minimum pairwise mappings for a graph edge; "
                         f"pixels of shared surface with surface mappings), got {t_npm!r}")


def t_npm_units(mode: str) -> str:
    """The unit of a pair count (and of ``t_npm``) for a mapping mode: ``"px"`` (surface) or ``"mappings"``."""
    return "px" if mode == "surface" else "mappings"


def resolve_t_npm(t_npm, mappings, *, image_sizes=None) -> tuple[int, str]:
    """The edge threshold in the units of ``mappings``, and how it was obtained.

    Parameters
    ----------
    t_npm : "auto" or int
        ``"auto"``: with surface mappings :data:`AUTO_T_NPM_FRACTION` of the median photo's
        pixel count (1 %: 3,072 px for 640 x 480 photos), with vertex and dense mappings the
        paper's 400 vertex mappings. A number: pixels of shared surface (surface mappings) or
        vertex mappings (vertex and dense mappings; :func:`scale_t_npm` converts for dense).
    mappings : o3d_seqcc.mappings.Mappings
    image_sizes : sequence of (width, height), optional
        Default ``mappings.image_sizes`` (surface ``"auto"`` only).

    Returns
    -------
    (int, str)
        The threshold and a sentence saying how it was derived (for messages and reports).

    Raises
    ------
    InputError
        ``t_npm`` is neither ``"auto"`` nor a positive integer; ``"auto"`` with surface mappings
        whose image sizes are unknown.
    """
    check_t_npm(t_npm)
    mode = getattr(mappings, "mode", "vertices")
    if mode != "surface":
        base = PAPER_T_NPM if t_npm == "auto" else int(t_npm)
        eff = scale_t_npm(base, mappings)
        how = f"t_npm={t_npm!r}: {base} vertex mappings" + (f" = {eff} {mode} mappings" if eff != base else "")
        return eff, how
    if t_npm != "auto":
        return int(t_npm), f"t_npm={int(t_npm)} px of shared surface"
    sizes = image_sizes if image_sizes is not None else getattr(mappings, "image_sizes", None)
    if not sizes:
        raise InputError("t_npm='auto' needs the photos' sizes, which these mappings do not record; give t_npm as a "
                         "number of pixels of shared surface")
    px = np.array([int(w) * int(h) for w, h in sizes], dtype=np.float64)
    med = float(np.median(px))
    eff = max(1, int(round(AUTO_T_NPM_FRACTION * med)))
    w, h = min(sizes, key=lambda s: abs(int(s[0]) * int(s[1]) - med))
    return eff, f"t_npm='auto': {AUTO_T_NPM_FRACTION:.0%} of a {w}x{h} photo = {eff} px of shared surface"


def build_graph(
    counts: Mapping[tuple[int, int], int], n_views: int, *, t_npm: int = PAPER_T_NPM, weight: str = "paper"
) -> nx.Graph:
    """Build the colour-correction weighted graph.

    Parameters
    ----------
    counts : dict[(int, int), int]
        Number of (filtered) pairwise mappings per view pair ``(a, b)``; the order of ``a`` and
        ``b`` does not matter, pairs absent from the dict have no mappings.
    n_views : int
        Number of views; every view becomes a node even without edges.
    t_npm : int, default 400
        Minimum number of mappings for an edge (``n >= t_npm``).
    weight : {"paper", "log"}, default "paper"
        ``"paper"``: ``1 - n / total``. With many pairs every such weight is close to 1, so
        Dijkstra then mostly minimises the number of steps and prefers one weak edge over two
        strong ones. ``"log"``: ``log(total / n)``, additive like the negative log of a product
        of overlap shares, so a path's cost reflects its weakest links. The default stays the
        paper's: on the 12-view synthetic ring (view 0 in the middle) and on fountain both give
        the same paths and seqcc results.

    Returns
    -------
    networkx.Graph
        Nodes ``0 .. n_views - 1``; edges carry ``n`` (int, mapping count) and ``weight``
        (float, ``1 - n / total`` with ``total`` the sum of the counts of **all** pairs, also the
        ones below the threshold; or ``log(total / n)``). The graph attribute ``total`` holds that sum and ``t_npm``
        the threshold used.

    Raises
    ------
    InputError
        Negative counts, a pair of a view with itself, or view indices out of range.

    Examples
    --------
    >>> import o3d_seqcc as sc
    >>> g = sc.build_graph({(0, 1): 900, (1, 2): 500, (0, 2): 100}, 3, t_npm=400)  # (0, 2) is below t_npm
    >>> sorted(g.edges())
    [(0, 1), (1, 2)]
    >>> round(g[0][1]['weight'], 3)  # 1 - n / (sum of n over all pairs)
    0.4
    """
    if weight not in WEIGHTS:
        raise ValueError(f"unknown graph weight {weight!r}; valid: {', '.join(WEIGHTS)}")
    n_views = int(n_views)
    if n_views < 1:
        raise InputError(f"n_views must be >= 1, got {n_views}")
    g = nx.Graph(t_npm=int(t_npm), weight=weight)
    g.add_nodes_from(range(n_views))
    clean: dict[tuple[int, int], int] = {}
    for (a, b), n in counts.items():
        a, b, n = int(a), int(b), int(n)
        if a == b:
            raise InputError(f"pair ({a}, {b}) maps a view to itself; pairs must join two different views")
        if not (0 <= a < n_views and 0 <= b < n_views):
            raise InputError(f"pair ({a}, {b}) is out of range for {n_views} views")
        if n < 0:
            raise InputError(f"pair ({a}, {b}) has a negative mapping count {n}")
        key = (min(a, b), max(a, b))
        clean[key] = clean.get(key, 0) + n
    total = int(sum(clean.values()))
    g.graph["total"] = total
    if total == 0:
        return g
    for (a, b), n in sorted(clean.items()):
        if n >= t_npm and n > 0:
            w = 1.0 - n / total if weight == "paper" else float(np.log(total / n))
            g.add_edge(a, b, n=n, weight=w)
    return g


def graph_edges(graph: nx.Graph) -> list[dict]:
    """The edges as a JSON-friendly list of ``{"a", "b", "n", "weight"}`` with ``a < b``, sorted."""
    out = []
    for a, b, d in graph.edges(data=True):
        a, b = min(a, b), max(a, b)
        out.append({"a": int(a), "b": int(b), "n": int(d["n"]), "weight": float(d["weight"])})
    return sorted(out, key=lambda e: (e["a"], e["b"]))


def correction_paths(graph: nx.Graph, reference: int) -> dict[int, list[int]]:
    """Dijkstra colour-correction path of every view to the reference.

    Parameters
    ----------
    graph : networkx.Graph
        From :func:`build_graph` (edge attribute ``weight``).
    reference : int
        Reference view index (a node of ``graph``).

    Returns
    -------
    dict[int, list[int]]
        ``view -> [view, ..., reference]`` (the reference maps to ``[reference]``); views with no
        path to the reference are absent. Ties between equal-cost paths are resolved
        deterministically by networkx's traversal order of the (sorted) edge insertion.
    """
    if reference not in graph:
        raise InputError(f"reference view {reference} is not a node of the graph (0..{graph.number_of_nodes() - 1})")
    from_ref = nx.single_source_dijkstra_path(graph, reference, weight="weight")
    return {int(v): [int(x) for x in reversed(p)] for v, p in sorted(from_ref.items())}


def choose_reference(graph: nx.Graph) -> int:
    """Pick a reference automatically (``reference="auto"``).

    Restricted to the largest connected component (ties: the component holding the lowest view
    index), the chosen view has the smallest sum of Dijkstra path costs to all other views of
    that component (closeness); ties go to the lowest index. A graph without edges gives view 0.
    All sources are solved at once by SciPy's compiled Dijkstra.

    Returns
    -------
    int
        View index.

    Examples
    --------
    >>> import o3d_seqcc as sc
    >>> sc.choose_reference(sc.build_graph({(0, 1): 900, (1, 2): 500}, 3, t_npm=400))  # the centre of the chain
    1
    """
    if graph.number_of_nodes() == 0:
        raise InputError("the graph has no views")
    comps = sorted(nx.connected_components(graph), key=lambda c: (-len(c), min(c)))
    comp = comps[0]
    if len(comp) == 1:
        return int(min(comp))
    nodes = np.array(sorted(comp), dtype=np.int64)
    cost = _total_path_costs(graph, nodes)
    best = int(np.flatnonzero(cost <= cost.min() + 1e-12)[0])  # ties: the lowest index
    return int(nodes[best])


def _total_path_costs(graph: nx.Graph, nodes: np.ndarray) -> np.ndarray:
    """Sum of the Dijkstra path costs from every node of a connected component to all others.

    All sources at once with SciPy's compiled Dijkstra on a sparse matrix: O(V (E + V log V))
    without Python-level work per edge (400 views with 30,000 edges: ~0.1 s).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    index = {int(v): i for i, v in enumerate(nodes)}
    edges = [(index[a], index[b], d["weight"]) for a, b, d in graph.subgraph(nodes.tolist()).edges(data=True)]
    a, b, w = (np.array(x) for x in zip(*edges))
    # zero weights are legal (a pair holding every mapping) but vanish in a sparse matrix: nudge them
    w = np.maximum(w.astype(np.float64), 1e-300)
    m = coo_matrix((w, (a, b)), shape=(len(nodes), len(nodes))).tocsr()
    dist = dijkstra(m, directed=False)
    return dist.sum(axis=1)


def scale_t_npm(t_npm: float, mappings) -> int:
    """Convert a threshold in vertex-mapping units to the units of ``mappings``.

    Parameters
    ----------
    t_npm : float
        Threshold as in the paper (vertex mappings; 400 = about 133 shared faces).
    mappings : o3d_seqcc.mappings.Mappings
        Uses ``mode`` and, for ``mode != "vertices"``, the pairs' ``face_ids``.

    Returns
    -------
    int
        ``t_npm`` unchanged for vertex mappings; for dense mappings ``t_npm`` times the mean
        number of mappings per shared face divided by 3 (pooled over the 8 pairs with the most
        mappings), at least ``t_npm``.
    """
    mode = getattr(mappings, "mode", "vertices")
    if mode == "vertices":
        return int(round(t_npm))
    # estimated on the (up to) 8 pairs with the most mappings: pairs may be built lazily
    counts = dict(getattr(mappings, "counts", None) or {k: pm.n for k, pm in mappings.pairs.items()})
    top = sorted(counts, key=lambda k: -counts[k])[:8]
    n_total, faces_total = 0, 0
    for key in top:
        pm = mappings.pairs[key]
        if pm.n == 0:
            continue
        n_total += int(pm.n)
        faces_total += int(np.unique(np.asarray(pm.face_ids)).size)
    if faces_total == 0:
        return int(round(t_npm))
    density = n_total / (3.0 * faces_total)
    scaled = int(round(t_npm * max(density, 1.0)))
    logger.info(
        "t_npm %s (vertex units) -> %d for %s mappings (%.1f mappings per shared face)",
        t_npm, scaled, mode, 3.0 * density,
    )
    return scaled


def mappings_summary(mappings: Mappings, *, t_npm: int | str) -> dict[str, Any]:
    """A JSON-friendly summary: pairs, pairs with at least ``t_npm`` (see
    :func:`resolve_t_npm`; e.g. :attr:`CorrectionSettings.t_npm
    <o3d_seqcc.correction.settings.CorrectionSettings.t_npm>`), totals, filter counts, timings."""
    st = mappings.filter_stats
    counts = sorted(mappings.counts.values())
    try:
        t_eff, _ = resolve_t_npm(t_npm, mappings)
    except InputError:
        t_eff = None
    return {
        "mode": mappings.mode,
        "views": mappings.n_views,
        "count_units": t_npm_units(mappings.mode),
        "pairs_with_mappings": len(counts),
        "t_npm": t_eff,
        "pairs_at_least_t_npm": None if t_eff is None else sum(c >= t_eff for c in counts),
        "mappings_total": mappings.total,
        "mappings_per_pair_median": counts[len(counts) // 2] if counts else 0,
        "filters (face-view incidences)": {
            k: st.get(k) for k in ("valid", "occluded", "depth_inconsistent", "oblique", "masked", "usable")
        },
        "views_seeing_nothing": st.get("views_seeing_nothing", []),
        "seconds": {k: round(v, 3) for k, v in st.get("timings", {}).items()},
    }
