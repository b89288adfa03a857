"""Learning the CRF weights with a structured SVM (1-slack cutting planes)."""
from __future__ import annotations

import itertools

import numpy as np
import pytest

from engine.crf.graph import build_graph, energies, energy, joint_feature
from engine.crf.labels import proposal_labels
from engine.crf.model import CRFSettings, CRFWeights
from engine.crf.scenes import make_scenes
from engine.crf.ssvm import _oracle, fit_ssvm, hamming_loss, solve_working_set, train_crf

K = 2


def test_loss_augmented_inference_is_the_most_violating_labelling():
    rng = np.random.default_rng(4)
    props, gts = make_scenes(1, seed=9, grid=K, false_per_class=0.3, dup_rate=0.3)
    props = props[0][:9]
    ystar = rng.random(len(props)) < 0.5
    w = CRFWeights.new(K, k=2)
    w.bias[:] = rng.normal(0, 0.5, 12)
    w.edge[:] = rng.normal(0, 0.5, w.edge.shape)
    out = _oracle((props, ystar), w, CRFSettings(), 2.0)
    graph = build_graph(props, w.k, w.grid)
    unary, pairwise = energies(graph, w)
    score_star = energy(unary, graph.edges, pairwise, ystar)

    def violation(y):
        return hamming_loss(ystar, y, 2.0) + energy(unary, graph.edges, pairwise, y) - score_star

    best = max(violation(np.array(b, bool)) for b in itertools.product([0, 1], repeat=len(props)))
    assert out["hinge"] == pytest.approx(best, abs=1e-4)
    assert out["hinge"] >= 0  # y* itself violates by 0
    assert hamming_loss([1, 1, 0], [0, 1, 1], 3.0) == 4.0


def _examples(n, seed):
    props, gts = make_scenes(n, seed=seed, grid=K)
    return [(p, proposal_labels(p, g)) for p, g in zip(props, gts)]


def test_cutting_planes_reduce_the_training_loss():
    examples = _examples(4, seed=11)
    res = fit_ssvm(examples, CRFWeights.new(K, k=2), lam=0.1, iterations=12, tol=0.0, miss_cost=1.0,
                   settings=CRFSettings(deterministic_time=5.0))
    h = res.history
    assert len(h) == 12
    # at w = 0 every labelling ties: the objective is the mean loss of flipping every label (miss cost 1: the count)
    assert res.objective["initial"] == pytest.approx(np.mean([len(y) for _, y in examples]))
    assert h[0]["primal"] == pytest.approx(res.objective["initial"])
    assert res.objective["final"] == min(x["primal"] for x in h) < 0.75 * res.objective["initial"]
    duals = [x["dual"] for x in h]
    assert all(b >= a - 1e-6 for a, b in zip(duals, duals[1:]))  # more planes never lower the dual
    assert all(x["dual"] <= x["primal"] + 1e-6 for x in h)  # weak duality: the primal values are exact
    assert duals[-1] > 0.5 * res.objective["final"]  # and the bound is not vacuous
    assert res.errors["final"] < res.errors["initial"]  # fewer wrong keep/drop decisions than "keep score > 0"
    assert res.weights.w0 > 0  # a higher detector score means keep


def test_working_set_dual_matches_a_known_solution():
    # one plane g with loss l: maximise a l - a^2 |g|^2 / (2 lam) on [0, 1] -> a = min(1, l lam / |g|^2)
    g = np.array([[3.0, 4.0]])
    alpha, dual = solve_working_set(g, np.array([2.0]), lam=5.0)
    assert alpha[0] == pytest.approx(0.4, abs=1e-6) and dual == pytest.approx(0.4, abs=1e-6)
    alpha, _ = solve_working_set(g, np.array([100.0]), lam=5.0)
    assert alpha[0] == pytest.approx(1.0, abs=1e-6)


def test_train_crf_is_deterministic_on_any_cluster(client):
    props, gts = make_scenes(3, seed=5, grid=K)
    kw = dict(iterations=3, lam=0.1, settings=CRFSettings(deterministic_time=5.0))
    report = {}
    w1 = train_crf(props, gts, client=client, report=report, **kw)
    w2 = train_crf(props, gts, **kw)
    np.testing.assert_array_equal(w1.vector(), w2.vector())
    assert report["spaces"] == 3 and len(report["history"]) == 3
    assert 0 < report["positives"] < report["proposals"]
    assert w1.grid == K


def test_training_arguments_are_checked():
    examples = _examples(1, seed=1)
    with pytest.raises(ValueError, match="lam"):
        fit_ssvm(examples, CRFWeights.new(K), lam=0)
    with pytest.raises(ValueError, match="no training space"):
        fit_ssvm([([], np.zeros(0, bool))], CRFWeights.new(K))
    with pytest.raises(ValueError, match="one ground-truth list"):
        train_crf([[]], [])
    # joint features of the empty labelling are zero: the untrained weights' energy is 0 there
    g = build_graph(examples[0][0], np.full(12, 2), K)
    assert not joint_feature(g, np.zeros(g.n, bool)).any()
