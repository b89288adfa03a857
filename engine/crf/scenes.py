"""Hand-made proposal scenes with ground truth, to test and benchmark the CRF without a trained detector.

A scene is one rectangular room: ground-truth boxes of its structure (floor,
ceiling, four walls, a door, windows) and furniture (tables with chairs around
them, a bookcase, a board), and the proposals a sliding-window detector would
plausibly make: a jittered true box per element, near duplicates of some (they
overlap the true box but count as false positives under the VOC rule), and
false positives of every class scattered through the room with lower but
overlapping scores.  What the CRF can learn here is the context the paper
relies on: duplicates of one class exclude each other, chairs sit near tables,
one floor and one ceiling per space.  Seeded and deterministic.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from engine.detection.proposals import Proposal
from tiles.classes import CLASS_CODES


def _box(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    return lo, hi - lo


def make_scene(seed: int, *, space_id: int = 0, grid: int = 4, dup_rate: float = 0.5, false_per_class: float = 1.5,
               origin: tuple[float, float, float] | None = None) -> tuple[list[Proposal], list[dict[str, Any]]]:
    """One room's proposals and its ground-truth element records (world boxes, yaw 0).

    Parameters
    ----------
    seed
        Everything random comes from this.
    space_id
        Stamped on proposals and ground truth.
    grid
        ``K`` of the occupancy patterns.
    dup_rate
        Chance that an element gets a near-duplicate proposal.
    false_per_class
        Mean number of scattered false positives per class.
    origin
        World position of the room's min corner (default: ``(20 * space_id, 0, 0)``).
    """
    rng = np.random.default_rng(seed)
    dims = np.array([rng.uniform(4, 9), rng.uniform(4, 8), rng.uniform(2.7, 3.3)])
    origin = np.array(origin if origin is not None else (20.0 * space_id, 0.0, 0.0))
    t = 0.2 / dims  # wall thickness and slab depth in unit-cube terms
    gts: list[tuple[int, np.ndarray, np.ndarray]] = []  # (class, P, S) in the unit cube
    gts.append((CLASS_CODES["floor"], *_box([0, 0, 0], [1, 1, t[2]])))
    gts.append((CLASS_CODES["ceiling"], *_box([0, 0, 1 - t[2]], [1, 1, 1])))
    gts.append((CLASS_CODES["wall"], *_box([0, 0, 0], [t[0], 1, 1])))
    gts.append((CLASS_CODES["wall"], *_box([1 - t[0], 0, 0], [1, 1, 1])))
    gts.append((CLASS_CODES["wall"], *_box([0, 0, 0], [1, t[1], 1])))
    gts.append((CLASS_CODES["wall"], *_box([0, 1 - t[1], 0], [1, 1, 1])))
    dx = rng.uniform(0.1, 0.7)
    gts.append((CLASS_CODES["door"], *_box([dx, 0, 0], [dx + 0.9 / dims[0], t[1], 2.1 / dims[2]])))
    for _ in range(int(rng.integers(1, 3))):
        wy = rng.uniform(0.1, 0.6)
        gts.append((CLASS_CODES["window"], *_box([1 - t[0], wy, 0.3], [1, wy + 1.2 / dims[1], 0.8])))
    for _ in range(int(rng.integers(1, 3))):
        c = rng.uniform([0.25, 0.3], [0.75, 0.7])
        half = np.array([0.8, 0.5]) / dims[:2]
        lo, hi = np.r_[c - half, 0.0], np.r_[c + half, 0.75 / dims[2]]
        gts.append((CLASS_CODES["table"], *_box(lo, hi)))
        for side in (-1, 1):
            cc = c + np.array([0, side * (half[1] + 0.35 / dims[1])])
            ch = np.array([0.25, 0.25]) / dims[:2]
            gts.append((CLASS_CODES["chair"], *_box(np.r_[cc - ch, 0.0], np.r_[cc + ch, 0.9 / dims[2]])))
    gts.append((CLASS_CODES["bookcase"], *_box([t[0], 0.75, 0], [t[0] + 0.4 / dims[0], 0.95, 0.7])))
    gts.append((CLASS_CODES["board"], *_box([0.3, 1 - t[1] - 0.02, 0.35], [0.6, 1 - t[1], 0.7])))

    def proposal(c: int, p: np.ndarray, s: np.ndarray, score: float, jitter: float) -> Proposal:
        s2 = np.clip(s * (1 + rng.normal(0, jitter, 3)), 1e-3, 1)
        p2 = np.clip(p + rng.normal(0, jitter, 3) * s, 0, 1 - s2)
        occ = rng.random((grid,) * 3) < (0.9 if score > 0 else 0.6)
        return Proposal(space_id, c, float(score), p2, s2, occ, origin + (p2 + s2 / 2) * dims, s2 * dims, 0.0)

    props: list[Proposal] = []
    for c, p, s in gts:
        if rng.random() < 0.9:
            props.append(proposal(c, p, s, rng.normal(1.0, 0.6), 0.03))
        if rng.random() < dup_rate:
            props.append(proposal(c, p, s, rng.normal(0.8, 0.6), 0.12))
    sizes = {c: s for c, _, s in gts}
    for c in sorted(sizes):
        for _ in range(int(rng.poisson(false_per_class))):
            s = sizes[c] * rng.uniform(0.7, 1.3, 3)
            s = np.clip(s, 1e-3, 1)
            p = rng.uniform(0, 1 - s)
            props.append(proposal(c, p, s, rng.normal(0.2, 0.6), 0.0))
    order = rng.permutation(len(props))
    props = [props[i] for i in order]
    gt = [{"class_code": int(c), "center": [float(v) for v in origin + (p + s / 2) * dims],
           "size": [float(v) for v in s * dims], "yaw": 0.0, "space": int(space_id)} for c, p, s in gts]
    return props, gt


def make_scenes(n: int, seed: int = 0, **kw: Any) -> tuple[list[list[Proposal]], list[list[dict[str, Any]]]]:
    """``n`` scenes (space ids 0..n-1), seeds derived from ``seed``."""
    props, gts = [], []
    for i in range(n):
        p, g = make_scene(seed * 100_003 + i, space_id=i, **kw)
        props.append(p)
        gts.append(g)
    return props, gts
