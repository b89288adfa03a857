"""The CRF graph: k_e nearest neighbours per class, order-free features, the graph bound."""
from __future__ import annotations

import numpy as np

from engine.crf.apply import select_elements
from engine.crf.graph import build_graph, edge_scale
from engine.crf.model import CRFSettings, CRFWeights, edge_feature_size, pair_index
from tests.engine.crf.helpers import CHAIR, TABLE, WALL, K, prop, random_proposals


def test_graph_joins_each_node_to_its_k_nearest_of_each_class():
    rng = np.random.default_rng(5)
    props = random_proposals(rng, 30, classes=3)
    k = np.zeros(12, int)
    k[:3] = [1, 2, 3]
    g = build_graph(props, k, K)
    cls = g.classes
    centre = np.array([p.position + p.size / 2 for p in props])
    adj = {i: set() for i in range(len(props))}
    for u, v in g.edges:
        assert cls[u] <= cls[v] and u != v
        adj[u].add(v)
        adj[v].add(u)
    assert len({tuple(e) for e in g.edges}) == g.m
    for v in range(len(props)):
        for e in range(3):
            others = [w for w in range(len(props)) if cls[w] == e and w != v]
            d = np.linalg.norm(centre[others] - centre[v], axis=1)
            nearest = {others[i] for i in np.argsort(d, kind="stable")[:k[e]]}
            assert nearest <= adj[v]  # its own k_e nearest are there (others may have chosen v too)
    assert g.m <= k[:3].sum() * len(props)
    assert g.phi.shape == (g.m, edge_feature_size(K))
    assert all(g.pairs[i] == pair_index(cls[u], cls[v]) for i, (u, v) in enumerate(g.edges))


def test_same_class_features_do_not_depend_on_order():
    rng = np.random.default_rng(1)
    a = prop(CHAIR, [0.1, 0.1, 0], [0.1, 0.1, 0.3], 1.0, occ=rng.random((K,) * 3) < 0.5)
    b = prop(CHAIR, [0.2, 0.1, 0], [0.2, 0.1, 0.3], 0.5, occ=rng.random((K,) * 3) < 0.5)
    g1 = build_graph([a, b], np.full(12, 1), K)
    g2 = build_graph([b, a], np.full(12, 1), K)
    np.testing.assert_allclose(g1.phi, g2.phi)
    t = prop(TABLE, [0.1, 0.3, 0], [0.3, 0.2, 0.25], 1.0)
    g3 = build_graph([t, a], np.full(12, 1), K)
    g4 = build_graph([a, t], np.full(12, 1), K)
    np.testing.assert_allclose(g3.phi, g4.phi)  # oriented by class: the table (7) is u, the chair (8) v
    k3 = K ** 3
    np.testing.assert_allclose(g3.phi[0, 2 * k3:2 * k3 + 3] * 12, t.size)  # divided by sum_e k_e = 12


def test_graph_bound_leaves_low_scores_to_their_unary():
    props = [prop(WALL, [0.1 * i, 0, 0], [0.05, 1, 1], 1.0 - 0.1 * i) for i in range(6)]
    w = CRFWeights.new(K, k=5)
    w.block(WALL, WALL, "const")[:] = -10.0 * edge_scale(w.k)  # every pair of walls excludes each other
    kept, info = select_elements(props, w, settings=CRFSettings(max_nodes_per_class=2))
    assert info["edges"] == 1
    # the two best exclude each other; the four outside the graph keep by their positive unary
    assert kept == [props[0]] + props[2:]
