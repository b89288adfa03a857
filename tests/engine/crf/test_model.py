"""The CRF of paper 4.1: graph, energies, the integer program against brute force, context, determinism."""
from __future__ import annotations

import itertools
import warnings

import numpy as np
import pytest

from engine.crf.model import (CLASS_PAIRS, CRFSettings, CRFWeights, apply_crf, build_graph, edge_feature_size,
                        edge_scale, energies, energy, fix_labels, flip_margins, joint_feature, metrics_block,
                        pair_index, rescored, select_elements, solve_fixed, solve_ip)
from engine.crf.scenes import make_scenes
from engine.detection.proposals import Proposal
from tiles.classes import CLASS_CODES

WALL, DOOR, CHAIR, TABLE = (CLASS_CODES[c] for c in ("wall", "door", "chair", "table"))
K = 2


def prop(cls, p, s, score, space=0, k=K, occ=None):
    p, s = np.asarray(p, float), np.asarray(s, float)
    occ = np.ones((k, k, k), bool) if occ is None else occ
    return Proposal(space, cls, float(score), p, s, occ, (p + s / 2) * 5, s * 5, 0.0)


def random_proposals(rng, n, k=K, space=0, classes=4):
    out = []
    for _ in range(n):
        s = rng.uniform(0.05, 0.5, 3)
        out.append(prop(int(rng.integers(0, classes)), rng.uniform(0, 1 - s), s, rng.normal(), space, k,
                        rng.random((k, k, k)) < 0.5))
    return out


def random_weights(rng, k=K, scale=1.0, kk=2):
    w = CRFWeights.new(k, k=kk)
    w.bias[:] = rng.normal(0, 0.5, len(w.bias))
    w.edge[:] = rng.normal(0, scale, w.edge.shape)
    return w


def brute_force(unary, edges, pairwise):
    n = len(unary)
    return max(energy(unary, edges, pairwise, np.array(bits, bool)) for bits in itertools.product([0, 1], repeat=n))


def tolerance(unary, pairwise, settings):
    top = max(np.abs(unary).max(initial=0), np.abs(pairwise).max(initial=0))
    return (len(unary) + len(pairwise)) * top / settings.resolution + 1e-9


# -- the integer program ---------------------------------------------------------------------------------

@pytest.mark.parametrize("seed", range(6))
def test_ip_optimum_equals_brute_force_on_random_energies(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 11))
    edges = np.array([(a, b) for a in range(n) for b in range(a + 1, n) if rng.random() < 0.5]).reshape(-1, 2)
    unary = rng.normal(0, 1, n)
    pairwise = rng.normal(0, 2, len(edges))
    settings = CRFSettings()
    y, info = solve_ip(unary, edges, pairwise, settings)
    assert info["status"] in ("OPTIMAL", "TRIVIAL")
    best = brute_force(unary, edges, pairwise)
    assert abs(energy(unary, edges, pairwise, y) - best) <= tolerance(unary, pairwise, settings)
    assert info["objective"] == pytest.approx(energy(unary, edges, pairwise, y))


@pytest.mark.parametrize("seed", range(4))
def test_select_elements_optimum_equals_brute_force(seed):
    rng = np.random.default_rng(100 + seed)
    props = random_proposals(rng, int(rng.integers(4, 11)))
    w = random_weights(rng)
    graph = build_graph(props, w.k, w.grid)
    unary, pairwise = energies(graph, w)
    kept, info = select_elements(props, w)
    y = np.array([any(p is q for q in kept) for p in props])
    assert info["status"] in ("OPTIMAL", "TRIVIAL") and info["nodes"] == len(props)
    assert abs(energy(unary, graph.edges, pairwise, y) - brute_force(unary, graph.edges, pairwise)) <= \
        tolerance(unary, pairwise, CRFSettings())
    # the energy is linear in the weights through the joint feature map (what the S-SVM relies on)
    assert w.vector() @ joint_feature(graph, y) == pytest.approx(energy(unary, graph.edges, pairwise, y))


@pytest.mark.parametrize("seed", range(4))
def test_fixed_labels_leave_the_best_labelling_of_the_free_nodes(seed):
    rng = np.random.default_rng(50 + seed)
    n = int(rng.integers(4, 10))
    edges = np.array([(a, b) for a in range(n) for b in range(a + 1, n) if rng.random() < 0.6]).reshape(-1, 2)
    unary, pairwise = rng.normal(0, 1, n), rng.normal(0, 2, len(edges))
    labels = np.where(rng.random(n) < 0.4, (rng.random(n) < 0.5).astype(int), -1)
    labels[0], labels[1] = 1, -1  # at least one fixed (kept) and one free node
    y, info = solve_fixed(unary, edges, pairwise, labels, CRFSettings())
    assert np.array_equal(y[labels >= 0], labels[labels >= 0] == 1)  # the fixed ones as given
    free = np.flatnonzero(labels < 0)
    best = -np.inf
    for bits in itertools.product([0, 1], repeat=len(free)):
        cand = labels == 1
        cand[free] = np.array(bits, bool)
        best = max(best, energy(unary, edges, pairwise, cand))
    assert abs(energy(unary, edges, pairwise, y) - best) <= tolerance(unary, pairwise, CRFSettings())
    assert info["objective"] == pytest.approx(energy(unary, edges, pairwise, y))
    # the reduced problem: only edges between free nodes; a kept fixed neighbour's energy moves into the unary
    u2, e2, p2 = fix_labels(unary, edges, pairwise, labels)
    assert np.all(labels[e2] < 0) and len(e2) == len(p2)
    assert np.all(u2[labels >= 0] == 0)
    for v in free:
        to_kept = [(a, b) for (a, b) in edges if v in (a, b) and labels[b if a == v else a] == 1]
        extra = sum(pairwise[i] for i, e in enumerate(edges) if tuple(e) in to_kept)
        assert u2[v] == pytest.approx(unary[v] + extra)
    assert solve_fixed(unary, edges, pairwise, None)[0].tolist() == solve_ip(unary, edges, pairwise)[0].tolist()


def test_classes_the_crf_does_not_decide_keep_the_detectors_decision():
    # a wall the CRF would drop (bias -10) and a negative-scored chair it would keep (bias +10)
    props = [prop(WALL, [0.1, 0.1, 0], [0.05, 0.8, 1], 0.7), prop(CHAIR, [0.5, 0.5, 0], [0.1, 0.1, 0.3], -0.4),
             prop(TABLE, [0.5, 0.4, 0], [0.2, 0.2, 0.3], 0.2)]
    w = CRFWeights.new(K, k=2)
    w.bias[WALL], w.bias[CHAIR], w.bias[TABLE] = -10.0, 10.0, 0.0
    w.block(CHAIR, TABLE, "const")[:] = -50.0  # keeping the chair would cost the table
    kept, _ = select_elements(props, w)
    assert [p.class_code for p in kept] == [CHAIR]
    w.decides[WALL] = w.decides[CHAIR] = False
    kept, _ = select_elements(props, w)
    assert [p.class_code for p in kept] == [WALL, TABLE]  # the detector's labels; the table freed of the chair


def test_isolated_nodes_follow_their_unary_sign():
    y, info = solve_ip(np.array([0.5, -0.2, 0.0, 3.0]), np.zeros((0, 2), int), np.zeros(0))
    assert info["status"] == "TRIVIAL"
    assert y.tolist() == [True, False, False, True]


def test_cp_sat_is_deterministic():
    rng = np.random.default_rng(7)
    props = random_proposals(rng, 40, classes=6)
    w = random_weights(rng, scale=0.5, kk=3)
    runs = [select_elements(props, w) for _ in range(2)]
    assert [id(p) for p in runs[0][0]] == [id(p) for p in runs[1][0]]
    assert runs[0][1]["objective"] == runs[1][1]["objective"]
    assert runs[0][1]["edges"] > 50  # a real problem, not a trivial one


def test_solver_limit_falls_back_with_a_warning():
    rng = np.random.default_rng(3)
    n = 60
    edges = np.array([(a, b) for a in range(n) for b in range(a + 1, n)])
    unary = rng.normal(0, 1, n)
    pairwise = rng.normal(0, 1, len(edges))
    y, info = solve_ip(unary, edges, pairwise, CRFSettings(deterministic_time=1e-6))
    assert info["status"] in ("FEASIBLE", "UNKNOWN")
    assert info["warning"]
    if info["status"] == "UNKNOWN":
        assert y.tolist() == (unary > 0).tolist()


# -- context: what the CRF is for ----------------------------------------------------------------------------

def duplicate_penalty(grid=K):
    w = CRFWeights.new(grid, k=3)
    # two walls where one is: at most one of them (features are divided by sum_e k_e: undo it)
    w.block(WALL, WALL, "iou")[:] = -8.0 * edge_scale(w.k)
    return w


def test_overlapping_walls_keep_the_better_one():
    a = prop(WALL, [0.00, 0, 0], [0.05, 1, 1], 1.0)
    b = prop(WALL, [0.01, 0, 0], [0.05, 1, 1], 0.6)  # overlaps a: IoU 0.67
    c = prop(WALL, [0.95, 0, 0], [0.05, 1, 1], 0.5)  # the opposite wall
    w = duplicate_penalty()
    kept, info = select_elements([a, b, c], w)
    assert kept == [a, c]
    assert info["status"] == "OPTIMAL"
    # without the pairwise term all three have positive scores and would stay
    kept0, _ = select_elements([a, b, c], CRFWeights.new(K, k=3))
    assert kept0 == [a, b, c]


def test_context_picks_the_wall_that_holds_the_door():
    """The better-scored wall loses because the detected door lies in the other one: not NMS, context."""
    a = prop(WALL, [0.00, 0, 0], [0.05, 1, 1], 1.0)
    b = prop(WALL, [0.02, 0, 0], [0.05, 1, 1], 0.8)
    door = prop(DOOR, [0.02, 0.4, 0], [0.05, 0.1, 0.7], 0.5)
    w = duplicate_penalty()
    w.block(WALL, DOOR, "iou")[:] = 20.0 * edge_scale(w.k)  # a door inside a wall supports that wall
    kept, _ = select_elements([a, b, door], w)
    assert kept == [b, door]
    w.block(WALL, DOOR, "iou")[:] = 0.0
    kept, _ = select_elements([a, b, door], w)
    assert kept == [a, door]


# -- the graph ----------------------------------------------------------------------------------------------

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


# -- weights ---------------------------------------------------------------------------------------------------

def test_weights_round_trip_through_files_and_the_model_slot(tmp_path):
    rng = np.random.default_rng(0)
    w = random_weights(rng, k=3)
    w.k[WALL] = 5
    npz, js = w.save(tmp_path / "crf.npz")
    assert npz.endswith("crf.npz") and js.endswith("crf.json")
    back = CRFWeights.load(tmp_path / "crf")
    np.testing.assert_array_equal(back.vector(), w.vector())
    assert back.grid == 3 and back.k[WALL] == 5 and back.decides.all()
    w.decides[CHAIR] = False
    w.save(tmp_path / "crf2")
    back = CRFWeights.load(tmp_path / "crf2")
    assert back.decides.tolist() == w.decides.tolist() and "chair" not in back.params()["decides"]
    # weights of version 1 (no crf_decides) load with every class decided
    arrays = {k: v for k, v in w.to_arrays().items() if k != "crf_decides"}
    old = CRFWeights.from_arrays(arrays, dict(w.params(), version=1))
    assert old.decides.all()

    class Slot:
        crf = None
        crf_arrays: dict = {}

    m = Slot()
    assert CRFWeights.from_model(m) is None
    w.store_in(m)
    assert all(k.startswith("crf_") for k in m.crf_arrays)
    np.testing.assert_array_equal(CRFWeights.from_model(m).vector(), w.vector())
    assert len(w.edge) == len(CLASS_PAIRS) == 78


def test_bad_inputs_are_refused():
    w = CRFWeights.new(K)
    with pytest.raises(ValueError, match="one space"):
        select_elements([prop(WALL, [0, 0, 0], [.1, .1, .1], 1, space=0),
                         prop(WALL, [0, 0, 0], [.1, .1, .1], 1, space=1)], w)
    with pytest.raises(ValueError, match="occupancy"):
        select_elements([prop(WALL, [0, 0, 0], [.1, .1, .1], 1, k=3), prop(WALL, [.5, 0, 0], [.1, .1, .1], 1, k=3)], w)
    with pytest.raises(ValueError, match="edge weights"):
        CRFWeights(1.0, np.zeros(12), np.zeros((78, 5)), 2, np.ones(12))
    with pytest.raises(ValueError):
        CRFSettings(linearization_level=3)
    with pytest.raises(ValueError, match="format"):
        CRFWeights.from_arrays(w.to_arrays(), {"format": "other"})
    assert select_elements([], w) == ([], {"space_id": None, "status": "EMPTY", "seconds": 0.0, "solver_seconds": 0.0,
                                           "nodes": 0, "edges": 0, "kept": 0, "objective": 0.0, "warning": None})


# -- all spaces as dask tasks ---------------------------------------------------------------------------------

def test_apply_crf_on_the_cluster_equals_space_by_space(client):
    props, _ = make_scenes(4, seed=3, grid=K)
    flat = [p for ps in props for p in ps]
    rng = np.random.default_rng(2)
    w = random_weights(rng, scale=0.3, kk=2)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        kept, report = apply_crf(flat, w, client=client)
    expected = []
    for ps in props:
        expected += select_elements(ps, w)[0]
    assert [(p.space_id, p.score) for p in kept] == [(p.space_id, p.score) for p in expected]
    assert report["spaces"] == 4 and report["proposals"] == len(flat) and report["kept"] == len(kept)
    assert sum(report["status"].values()) == 4
    assert 0 < report["solve_seconds"]["median"] <= report["solve_seconds"]["max"]
    assert 0 < len(kept) < len(flat)
    block = metrics_block(report)
    assert set(block) == {"spaces", "solve_seconds", "status", "proposals", "kept", "decides"}
    assert block["kept"] == len(kept) and len(block["decides"]) == 12


def test_apply_crf_submits_the_largest_spaces_first_and_reports_by_space(client, monkeypatch):
    """Spaces with most proposals are submitted first (no long solve left for the end); kept set, margins and
    the per-space report stay in space order, as when submitted by id."""
    import engine.crf.model as crf

    props, _ = make_scenes(4, seed=3, grid=K)
    flat = [p for ps in props for p in ps]
    w = random_weights(np.random.default_rng(2), scale=0.3, kk=2)
    sent = []
    real = crf.run_tasks

    def spy(fn, items, **kw):
        sent.append([len(it) for it in items])
        return real(fn, items, **kw)

    monkeypatch.setattr(crf, "run_tasks", spy)
    kept, report = apply_crf(flat, w, client=client)
    assert sent[0] == sorted(sent[0], reverse=True) and sent[0] != [len(ps) for ps in props]
    margins = [p.extra["crf_margin"] for p in flat]
    alone = [apply_crf(list(ps), w) for ps in props]  # one space at a time, here
    assert [(p.space_id, p.score) for p in kept] == [(p.space_id, p.score) for ks, _ in alone for p in ks]
    assert margins == [p.extra["crf_margin"] for p in flat]

    def info(i):
        return i["space_id"], i["status"], i["nodes"], i["edges"], i["kept"]

    assert [info(i) for i in report["per_space"]] == [info(i) for _, r in alone for i in r["per_space"]]


def test_margins_agree_with_the_kept_set_and_rank_in_context():
    a = prop(WALL, [0.00, 0, 0], [0.05, 1, 1], 1.0)
    b = prop(WALL, [0.01, 0, 0], [0.05, 1, 1], 0.6)
    c = prop(WALL, [0.95, 0, 0], [0.05, 1, 1], 0.5)
    kept, _ = select_elements([a, b, c], duplicate_penalty())
    margins = {id(p): p.extra["crf_margin"] for p in (a, b, c)}
    assert all((margins[id(p)] > 0) == (p in kept) for p in (a, b, c))
    # b scores above c but is a duplicate of the kept a: in context it ranks below c
    assert margins[id(b)] < 0 < margins[id(c)] < margins[id(a)]
    r = rescored([a, b, c])
    assert [p.score for p in r] == [margins[id(p)] for p in (a, b, c)] and a.score == 1.0
    with pytest.raises(ValueError, match="margin"):
        rescored([prop(WALL, [0, 0, 0], [.1, .1, .1], 1)])
    rng = np.random.default_rng(3)
    for _ in range(3):  # at the optimum no single flip gains: kept >= 0, dropped <= 0
        n = 9
        edges = np.array([(i, j) for i in range(n) for j in range(i + 1, n) if rng.random() < 0.6])
        u, pw = rng.normal(size=n), rng.normal(size=len(edges))
        y, _ = solve_ip(u, edges, pw)
        m = flip_margins(u, edges, pw, y)
        assert np.all(m[y] >= -1e-5) and np.all(m[~y] <= 1e-5)


def test_solver_runs_with_one_worker_linearization_2_a_fixed_seed_and_limits(monkeypatch):
    from ortools.sat.python import cp_model

    seen = []

    class Recording(cp_model.CpSolver):
        def solve(self, model, *args, **kwargs):
            p = self.parameters
            seen.append((p.num_workers, p.linearization_level, p.random_seed, p.max_deterministic_time,
                         p.max_time_in_seconds))
            return super().solve(model, *args, **kwargs)

    monkeypatch.setattr(cp_model, "CpSolver", Recording)
    edges = np.array([(0, 1), (1, 2), (0, 2)])
    y, info = solve_ip(np.array([1.0, 0.5, -0.2]), edges, np.array([-2.0, 0.3, 0.1]))
    assert info["status"] == "OPTIMAL"
    assert seen == [(1, 2, 0, 20.0, 30.0)]  # the defaults of engine/crf/crf.yaml
    solve_ip(np.array([1.0, 0.5, -0.2]), edges, np.array([-2.0, 0.3, 0.1]),
             CRFSettings(seed=7, linearization_level=0, deterministic_time=3.0, time_limit=4.0))
    assert seen[-1] == (1, 0, 7, 3.0, 4.0)


def test_apply_crf_reports_a_space_not_solved_to_optimality(client):
    rng = np.random.default_rng(7)
    hard = random_proposals(rng, 120, classes=12)
    w = random_weights(rng, scale=1.0, kk=6)
    easy = [prop(WALL, [0.0, 0, 0], [0.05, 1, 1], 1.0, space=1)]
    with pytest.warns(RuntimeWarning, match="not solved to optimality|no solution"):
        kept, report = apply_crf(hard + easy, w, client=client,
                                 settings=CRFSettings(deterministic_time=1e-6, time_limit=5.0))
    status = report["status"]
    assert sum(status.values()) == 2 and status.get("TRIVIAL") == 1
    assert status.get("FEASIBLE", 0) + status.get("UNKNOWN", 0) == 1
    bad = [i for i in report["per_space"] if i["status"] != "TRIVIAL"][0]
    assert bad["warning"] and bad["space_id"] == hard[0].space_id
    assert easy[0] in kept  # the other space is unaffected
