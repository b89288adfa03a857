"""Choosing the CRF's miss cost and the classes it decides by building-wise folds."""
from __future__ import annotations

import numpy as np
import pytest

from engine.crf.labels import proposal_labels
from engine.crf.model import N_CLASSES, CRFSettings, CRFWeights
from engine.crf.scenes import make_scenes
from engine.crf.ssvm import train_crf
from engine.crf.validation import MARGIN, choose, gate, set_ap
from engine.detection.proposals import Proposal
from tiles.classes import CLASS_CODES

K = 2
WALL, CHAIR = CLASS_CODES["wall"], CLASS_CODES["chair"]


def world_prop(cls, center, size, score, space=0):
    c, s = np.asarray(center, float), np.asarray(size, float)
    return Proposal(space, cls, score, c / 10, s / 10, np.ones((K,) * 3, bool), c, s, 0.0)


def gt(cls, center, size):
    return {"class_code": cls, "center": list(center), "size": list(size), "yaw": 0.0}


def test_set_ap_scores_only_the_kept_proposals():
    truth = [gt(WALL, [1, 5, 1.5], [0.2, 8, 3]), gt(WALL, [9, 5, 1.5], [0.2, 8, 3])]
    props = [world_prop(WALL, [1, 5, 1.5], [0.2, 8, 3], 0.9),  # true
             world_prop(WALL, [5, 5, 1.5], [0.2, 8, 3], 0.8),  # false
             world_prop(WALL, [9, 5, 1.5], [0.2, 8, 3], -0.5)]  # true, negative score
    ap_all = set_ap([props], [truth], [np.ones(3, bool)])
    ap_pos = set_ap([props], [truth], [np.array([True, True, False])])
    # all three: recall 1/2 at precision 1, 2/2 at 2/3 -> 0.5 + 0.5 * 2/3; the positive ones: recall 1/2 only
    assert ap_all[WALL] == pytest.approx(0.5 + 0.5 * 2 / 3)
    assert ap_pos[WALL] == pytest.approx(0.5)
    assert np.isnan(ap_all[CHAIR])  # no chair in the ground truth
    # a proposal that was a duplicate becomes the match when the better one is not kept
    dup = [world_prop(WALL, [1, 5, 1.5], [0.2, 8, 3], 0.9), world_prop(WALL, [1.05, 5, 1.5], [0.2, 8, 3], 0.5)]
    assert set_ap([dup], [truth[:1]], [np.array([False, True])])[WALL] == pytest.approx(1.0)


def test_gate_needs_the_margin_and_ground_truth():
    ap_set = np.full(N_CLASSES, 0.5)
    ap_crf = np.full(N_CLASSES, 0.5)
    ap_crf[WALL] = 0.5 + MARGIN + 1e-9
    ap_crf[CHAIR] = 0.5 + MARGIN / 2
    ap_crf[0] = ap_set[0] = np.nan
    d = gate(ap_crf, ap_set)
    assert d[WALL] and not d[CHAIR] and not d[0] and d.sum() == 1


def _scenes(n_buildings, per_building=2):
    props, gts, blds = [], [], []
    for b in range(n_buildings):
        p, g = make_scenes(per_building, seed=40 + b, grid=K)
        props += p
        gts += g
        blds += [f"b{b}"] * per_building
    return props, gts, blds


def test_choose_never_decides_a_space_with_weights_it_trained_on():
    props, gts, blds = _scenes(3)
    labels = [proposal_labels(p, g) for p, g in zip(props, gts)]
    for ps, y in zip(props, labels):  # one true wall per space that the detector's own set (score > 0) misses
        true_walls = [p for p, t in zip(ps, y) if t and p.class_code == WALL]
        min(true_walls, key=lambda p: p.score).score = -5.0
    labels = [proposal_labels(p, g) for p, g in zip(props, gts)]
    seen: list[tuple[float, set[int]]] = []

    def fit(examples, init, cost):
        seen.append((cost, {id(ex[0][0]) for ex in examples}))
        w = CRFWeights.new(init.grid, k=init.k.tolist()[0])
        w.bias[CHAIR] = -100.0  # drops every chair: worse than the detector's own set
        w.bias[WALL] = 100.0 if cost > 1 else 0.0  # keeps every wall (recall up) only at the larger cost
        return w

    cost, decides, report = choose(props, gts, labels, blds, [1.0, 4.0], CRFWeights.new(K, k=2), fit,
                                   settings=CRFSettings(deterministic_time=5.0))
    assert report["folds"] == 3 and len(seen) == 6  # leave one building out, per candidate
    first = {b: {id(p[0]) for p, bb in zip(props, blds) if bb == b} for b in set(blds)}
    for _, trained in seen:
        assert sum(trained >= first[b] for b in first) == 2  # two buildings in, the third out
        assert sum(bool(trained & first[b]) for b in first) == 2
    assert not decides[CHAIR]  # the detector keeps its chairs
    c1, c4 = report["candidates"]["1"], report["candidates"]["4"]
    assert c1["kept_set"]["wall"] == report["detector_set"]["wall"] and "wall" not in c1["decides"]
    assert c4["kept_set"]["wall"] >= report["detector_set"]["wall"] + 100 * MARGIN and c4["decides"] == ["wall"]
    assert cost == 4.0 and decides[WALL] and decides.sum() == 1 and c4["gated_map"] > c1["gated_map"]
    assert set(report["decides"]) == {c for c, d in zip(report["detector_set"], decides) if d}


def test_train_crf_with_buildings_fixes_the_undecided_classes(client):
    props, gts, blds = _scenes(2)
    kw = dict(iterations=3, lam=0.1, settings=CRFSettings(deterministic_time=5.0), miss_costs=[2.0, 8.0])
    report: dict = {}
    w1 = train_crf(props, gts, buildings=blds, client=client, report=report, **kw)
    w2 = train_crf(props, gts, buildings=blds, **kw)
    np.testing.assert_array_equal(w1.vector(), w2.vector())
    assert w1.decides.tolist() == w2.decides.tolist()
    v = report["validation"]
    assert v["folds"] == 2 and set(v["candidates"]) == {"2", "8"} and report["miss_cost"] in (2.0, 8.0)
    assert w1.decides.tolist() == [c in v["decides"] for c in v["detector_set"]]
    single: dict = {}
    kw["miss_costs"] = [8.0, 32.0]  # no buildings: nothing to choose on, so crf.ssvm.miss-cost (2), every class
    w3 = train_crf(props, gts, report=single, **kw)
    assert single["miss_cost"] == 2.0 and single["validation"] is None and w3.decides.all()
    one: dict = {}
    train_crf(props, gts, buildings=["b0"] * len(props), report=one, **kw)  # one building: the same
    assert one["miss_cost"] == 2.0 and one["validation"]["folds"] == 0
    with pytest.raises(ValueError, match="building label"):
        train_crf(props, gts, buildings=blds[:1], **kw)


def test_the_classes_always_kept_are_kept_by_the_detectors_set_too():
    """A true ceiling the detector scored -5 is in both sets (``crf.keep-classes``): the CRF's kept set does
    not beat the detector's own on ceilings for that alone, so it does not come to decide them."""
    ceiling = CLASS_CODES["ceiling"]
    props, gts, blds = _scenes(3)
    for ps, g in zip(props, gts):
        ps.append(world_prop(ceiling, [5, 5, 3], [10, 10, 0.05], -5.0, space=ps[0].space_id))
        g.append(gt(ceiling, [5, 5, 3], [10, 10, 0.05]))
    labels = [proposal_labels(p, g) for p, g in zip(props, gts)]

    def fit(examples, init, cost):
        return CRFWeights.new(init.grid, k=init.k.tolist()[0])

    _, decides, report = choose(props, gts, labels, blds, [2.0], CRFWeights.new(K, k=2), fit,
                                settings=CRFSettings(deterministic_time=5.0))
    assert report["detector_set"]["ceiling"] == report["candidates"]["2"]["kept_set"]["ceiling"]
    assert not decides[ceiling]
    _, _, off = choose(props, gts, labels, blds, [2.0], CRFWeights.new(K, k=2), fit,
                       settings=CRFSettings(deterministic_time=5.0, keep_classes=()))
    assert off["detector_set"]["ceiling"] < report["detector_set"]["ceiling"]  # without the rule it loses them
