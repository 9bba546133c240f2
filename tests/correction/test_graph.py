"""Colour-correction graph: weights, threshold, Dijkstra paths, automatic reference."""

from __future__ import annotations

from types import SimpleNamespace

import networkx as nx
import numpy as np
import pytest

from o3d_seqcc.errors import InputError
from o3d_seqcc.correction.graph import build_graph, choose_reference, correction_paths, graph_edges, scale_t_npm

# 6 views; view 5 only shares a few mappings (below t_npm) -> isolated
COUNTS = {(0, 1): 1000, (1, 2): 3000, (0, 2): 500, (2, 3): 2000, (1, 3): 400, (3, 4): 600, (0, 5): 100, (4, 5): 399}
TOTAL = sum(COUNTS.values())


def test_weights_threshold_and_nodes():
    g = build_graph(COUNTS, 6, t_npm=400)
    assert sorted(g.nodes) == list(range(6))
    assert g.graph["total"] == TOTAL
    kept = {k for k, n in COUNTS.items() if n >= 400}
    assert {tuple(sorted(e)) for e in g.edges} == kept
    for (a, b), n in COUNTS.items():
        if n >= 400:
            assert g[a][b]["n"] == n
            # normalised by the sum over ALL pairs (also the ones below t_npm)
            assert g[a][b]["weight"] == pytest.approx(1 - n / TOTAL)
    assert g.degree(5) == 0
    edges = graph_edges(g)
    assert edges[0] == {"a": 0, "b": 1, "n": 1000, "weight": pytest.approx(1 - 1000 / TOTAL)}


def test_order_of_pair_keys_does_not_matter():
    g1 = build_graph({(1, 0): 500, (2, 1): 700}, 3, t_npm=1)
    g2 = build_graph({(0, 1): 500, (1, 2): 700}, 3, t_npm=1)
    assert graph_edges(g1) == graph_edges(g2)


def test_dijkstra_paths_known_answer():
    g = build_graph(COUNTS, 6, t_npm=400)
    paths = correction_paths(g, 0)
    w = {k: 1 - n / TOTAL for k, n in COUNTS.items()}
    # 2 -> 0: direct (w02) vs via 1 (w12 + w01): the direct edge costs less than two hops
    assert w[(0, 2)] < w[(1, 2)] + w[(0, 1)]
    assert paths[0] == [0]
    assert paths[1] == [1, 0]
    assert paths[2] == [2, 0]
    # 3 -> 0: via 1 (w13 + w01) or via 2 (w23 + w02)
    via1, via2 = w[(1, 3)] + w[(0, 1)], w[(2, 3)] + w[(0, 2)]
    assert paths[3] == ([3, 1, 0] if via1 < via2 else [3, 2, 0])
    assert paths[4][:2] == [4, 3] and paths[4][2:] == paths[3][1:]
    assert 5 not in paths  # unreachable views are absent
    # every path is a real shortest path
    for v, p in paths.items():
        assert nx.path_weight(g, p, "weight") == pytest.approx(nx.dijkstra_path_length(g, v, 0))


def test_choose_reference_min_total_cost_in_largest_component():
    g = build_graph(COUNTS, 6, t_npm=400)
    ref = choose_reference(g)
    comp = nx.node_connected_component(g, 0)
    costs = {v: sum(nx.single_source_dijkstra_path_length(g, v).values()) for v in comp}
    assert ref == min(costs, key=lambda v: (costs[v], v))
    assert ref != 5


def test_choose_reference_ties_and_no_edges():
    assert choose_reference(build_graph({}, 4)) == 0
    # symmetric chain 0-1-2: the middle one wins; 2 components: the larger one
    g = build_graph({(0, 1): 500, (1, 2): 500, (3, 4): 10000}, 5, t_npm=400)
    assert choose_reference(g) == 1
    # two equal components of 2: ties -> lowest index
    g = build_graph({(0, 1): 500, (2, 3): 500}, 4, t_npm=400)
    assert choose_reference(g) == 0


def test_bad_counts():
    with pytest.raises(InputError):
        build_graph({(0, 0): 5}, 2)
    with pytest.raises(InputError):
        build_graph({(0, 3): 5}, 2)
    with pytest.raises(InputError):
        build_graph({(0, 1): -1}, 2)
    with pytest.raises(InputError):
        correction_paths(build_graph({}, 2), 5)


def test_scale_t_npm_dense():
    vert = SimpleNamespace(mode="vertices", pairs={})
    assert scale_t_npm(400, vert) == 400
    # dense: 2 pairs, 10 faces each with 30 mappings per face -> 10 per face-vertex
    pm = SimpleNamespace(n=300, face_ids=np.repeat(np.arange(10), 30))
    dense = SimpleNamespace(mode="dense", pairs={(0, 1): pm, (1, 2): pm})
    assert scale_t_npm(400, dense) == 4000


def test_log_weights_prefer_two_strong_edges_over_one_weak():
    counts = {(0, 1): 5000, (1, 2): 5000, (0, 2): 450, (2, 3): 100}
    paper = build_graph(counts, 4, t_npm=400)
    log = build_graph(counts, 4, t_npm=400, weight="log")
    total = sum(counts.values())
    assert log[0][1]["weight"] == pytest.approx(np.log(total / 5000))
    assert correction_paths(paper, 0)[2] == [2, 0]  # weights ~1 each: fewest steps
    assert correction_paths(log, 0)[2] == [2, 1, 0]
    with pytest.raises(ValueError, match="paper"):
        build_graph(counts, 4, weight="nope")


def test_auto_reference_equals_the_brute_force_closeness_on_random_graphs():
    import networkx as nx

    rng = np.random.default_rng(7)
    for trial in range(20):
        V = int(rng.integers(3, 40))
        counts = {(a, b): int(rng.integers(0, 3000)) for a in range(V) for b in range(a + 1, V) if rng.random() < 0.3}
        g = build_graph(counts, V, t_npm=400)
        if g.number_of_edges() == 0:
            continue
        comp = sorted(nx.connected_components(g), key=lambda c: (-len(c), min(c)))[0]
        sub = g.subgraph(comp)
        cost = {v: sum(nx.single_source_dijkstra_path_length(sub, v, weight="weight").values()) for v in sorted(comp)}
        best = min(cost.values())
        assert choose_reference(g) == min(v for v, c in cost.items() if c <= best + 1e-12)
