"""The CRF of one space and of every space: optimum, context, undecided classes, determinism, dask tasks."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from engine.crf.apply import apply_crf, flip_margins, metrics_block, rescored, select_elements
from engine.crf.graph import build_graph, edge_scale, energies, energy, joint_feature
from engine.crf.model import CRFSettings, CRFWeights
from engine.crf.scenes import make_scenes
from engine.crf.solve import solve_ip
from tests.engine.crf.helpers import (
    CEILING,
    CHAIR,
    DOOR,
    FLOOR,
    TABLE,
    WALL,
    K,
    brute_force,
    duplicate_penalty,
    prop,
    random_proposals,
    random_weights,
    tolerance,
)


@pytest.mark.parametrize("seed", range(4))
def test_select_elements_optimum_equals_brute_force(seed):
    rng = np.random.default_rng(100 + seed)
    props = random_proposals(rng, int(rng.integers(4, 11)))
    w = random_weights(rng)
    graph = build_graph(props, w.k, w.grid)
    unary, pairwise = energies(graph, w)
    kept, info = select_elements(props, w, settings=CRFSettings(keep_classes=()))  # every node free
    y = np.array([any(p is q for q in kept) for p in props])
    assert info["status"] in ("OPTIMAL", "TRIVIAL") and info["nodes"] == len(props)
    assert abs(energy(unary, graph.edges, pairwise, y) - brute_force(unary, graph.edges, pairwise)) <= \
        tolerance(unary, pairwise, CRFSettings())
    # the energy is linear in the weights through the joint feature map (what the S-SVM relies on)
    assert w.vector() @ joint_feature(graph, y) == pytest.approx(energy(unary, graph.edges, pairwise, y))


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


def test_cp_sat_is_deterministic():
    rng = np.random.default_rng(7)
    props = random_proposals(rng, 40, classes=6)
    w = random_weights(rng, scale=0.5, kk=3)
    runs = [select_elements(props, w) for _ in range(2)]
    assert [id(p) for p in runs[0][0]] == [id(p) for p in runs[1][0]]
    assert runs[0][1]["objective"] == runs[1][1]["objective"]
    assert runs[0][1]["edges"] > 50  # a real problem, not a trivial one


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
    assert set(block) == {"spaces", "solve_seconds", "status", "proposals", "kept", "decides", "always_kept"}
    assert block["kept"] == len(kept) and len(block["decides"]) == 12 and block["always_kept"] == ["ceiling", "floor"]


def test_apply_crf_submits_the_largest_spaces_first_and_reports_by_space(client, monkeypatch):
    """Spaces with most proposals are submitted first (no long solve left for the end); kept set, margins and
    the per-space report stay in space order, as when submitted by id."""
    import engine.crf.apply as crf

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


def test_a_spaces_ceiling_and_floor_are_kept_whatever_their_score():
    # a ceiling and a floor the detector scored <= 0 (surfaces unlike the training ones), a wall it scored < 0
    props = [prop(CEILING, [0, 0, 0.95], [1, 1, 0.05], -0.6), prop(FLOOR, [0, 0, 0], [1, 1, 0.05], 0.0),
             prop(WALL, [0.1, 0.1, 0], [0.05, 0.8, 1], -0.3)]
    w = CRFWeights.new(K, k=2)
    w.decides[:] = False  # every class keeps the detector's decision...
    kept, _ = select_elements(props, w)
    assert [p.class_code for p in kept] == [CEILING, FLOOR]  # ...but a space's ceiling and floor
    w.decides[:] = True
    w.bias[CEILING] = w.bias[FLOOR] = -10.0  # a CRF that would drop them keeps them too
    kept, _ = select_elements(props, w)
    assert [p.class_code for p in kept] == [CEILING, FLOOR]
    kept, _ = select_elements(props, w, settings=CRFSettings(keep_classes=()))
    assert kept == []
    with pytest.raises(ValueError, match="keep-classes"):
        CRFSettings(keep_classes="ceiling,attic")


def test_a_sure_proposal_is_kept_whatever_its_score():
    """A wall added at a side of its space (``extra["sure"]``, engine.detection.sides) is kept as a space's ceiling
    is: by the detector's decision and by a CRF that would drop it; a wall beside it with the same score is not."""
    from engine.detection.proposals import SURE

    sure = prop(WALL, [0.0, 0.1, 0], [0.05, 0.8, 1], -1.2)
    sure.extra[SURE] = True
    other = prop(WALL, [0.9, 0.1, 0], [0.05, 0.8, 1], -1.2)
    w = CRFWeights.new(K, k=2)
    w.decides[:] = False
    kept, _ = select_elements([sure, other], w, settings=CRFSettings(keep_classes=()))
    assert kept == [sure]
    w.decides[:] = True
    w.bias[WALL] = -10.0
    kept, _ = select_elements([sure, other], w, settings=CRFSettings(keep_classes=()))
    assert kept == [sure]
