"""Shared helpers of the CRF tests: hand-placed and random proposals, random weights, brute force."""
from __future__ import annotations

import itertools

import numpy as np

from engine.crf.graph import edge_scale, energy
from engine.crf.model import CRFWeights
from engine.detection.proposals import Proposal
from tiles.classes import CLASS_CODES

WALL, DOOR, CHAIR, TABLE = (CLASS_CODES[c] for c in ("wall", "door", "chair", "table"))
CEILING, FLOOR = CLASS_CODES["ceiling"], CLASS_CODES["floor"]
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


def duplicate_penalty(grid=K):
    w = CRFWeights.new(grid, k=3)
    # two walls where one is: at most one of them (features are divided by sum_e k_e: undo it)
    w.block(WALL, WALL, "iou")[:] = -8.0 * edge_scale(w.k)
    return w
