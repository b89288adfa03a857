"""The integer program of paper 4.1 against brute force; fixed labels; the solver's settings and limits."""
from __future__ import annotations

import itertools

import numpy as np
import pytest

from engine.crf.graph import energy
from engine.crf.model import CRFSettings
from engine.crf.solve import fix_labels, solve_fixed, solve_ip
from tests.engine.crf.helpers import brute_force, tolerance


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


def test_isolated_nodes_follow_their_unary_sign():
    y, info = solve_ip(np.array([0.5, -0.2, 0.0, 3.0]), np.zeros((0, 2), int), np.zeros(0))
    assert info["status"] == "TRIVIAL"
    assert y.tolist() == [True, False, False, True]


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
