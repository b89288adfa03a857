"""Rejoining the pieces cut off by refinement across the refined space's border (issue 8: hard buildings).

The refinement (:mod:`engine.spaces.refine`) parses a large space again on its own
points and may split it.  A piece of it can belong to a space *beyond* its
border: the building-wide merging had glued the end of a hallway to a room
(a leaky face), the refinement cut it off, and it is left a space of its own
beside the rest of its hallway, with an open face between the two that the
building-wide agglomeration had refused (the face was a small part of the
large space's boundary).

:func:`rejoin_pieces` runs the agglomeration of :mod:`engine.spaces.merging` once
more over the final spaces, counting only the faces without a divider that
touch a refined piece (the faces between two spaces that were not refined
were decided already and are not counted again), and never joining two
pieces of the same refinement (it split them on purpose).  The openness of
two groups is their open faces' length over the smaller group's boundary,
and the most open pair joins first while it is at least ``min_open_ratio``;
faces to nearly unscanned spaces do not count (``min_scanned_density``).
"""
from __future__ import annotations

import numpy as np

from engine.spaces.merging import Edge, MergeRules
from engine.spaces.slicing import Box


def rejoin_pieces(cells: list[Box], edges: list[Edge], labels: np.ndarray, sides: np.ndarray, source: np.ndarray,
                  bin_width: float, rules: MergeRules | None = None) -> np.ndarray:
    """New space of every space after rejoining refined pieces with their neighbours (a graph partition).

    Parameters
    ----------
    cells
        All cells (the building's and the refinements'), in bins of their own frames.
    edges
        Their faces; ``edge.divider`` None: no divider.
    labels
        Space of each cell (-1: none).
    sides
        ``(len(edges), 2)``: the space on each side of each edge (-1: none).
    source
        Per space: the refinement it is a piece of, -1 when it was not refined.
    bin_width
        Metres per bin.
    rules
        ``min_open_ratio`` and ``min_scanned_density``.

    Returns
    -------
    numpy.ndarray
        ``group[s]``: the space ``s`` joins (the smallest id of its group); ``s`` itself when unchanged.
    """
    r = rules or MergeRules()
    n = len(source)
    group = np.arange(n, dtype=np.int64)
    if n == 0 or not edges or not np.any(source >= 0):
        return group
    lab = np.asarray(labels, dtype=np.int64)
    box = np.array([[c.u0, c.u1, c.v0, c.v1] for c in cells], dtype=np.float64).reshape(-1, 4) * bin_width
    w, h = box[:, 1] - box[:, 0], box[:, 3] - box[:, 2]
    ok = lab >= 0
    count = np.array([c.count for c in cells], dtype=np.float64)
    area = np.bincount(lab[ok], weights=(w * h)[ok], minlength=n)
    points = np.bincount(lab[ok], weights=count[ok], minlength=n)
    perimeter = np.bincount(lab[ok], weights=(2.0 * (w + h))[ok], minlength=n)
    sa, sb = np.asarray(sides, dtype=np.int64).reshape(-1, 2).T
    length = np.array([e.length_bins for e in edges], dtype=np.float64) * bin_width
    free = np.array([e.divider is None for e in edges], dtype=bool)
    inner = (sa == sb) & (sa >= 0)
    boundary = perimeter - np.bincount(sa[inner], weights=2.0 * length[inner], minlength=n)
    density = np.where(area > 0, points / np.maximum(area, 1e-12), 0.0)
    scanned = points > 0
    level = float(np.median(density[scanned])) if scanned.any() else 0.0
    sparse = density < r.min_scanned_density * level
    both = (sa >= 0) & (sb >= 0) & (sa != sb)
    use = both & free
    use[use] &= (source[sa[use]] >= 0) | (source[sb[use]] >= 0)  # only faces touching a refined piece
    use[use] &= sparse[sa[use]] == sparse[sb[use]]
    ea, eb, el = sa[use], sb[use], length[use]
    if not len(ea):
        return group
    # the refinements each group holds pieces of (two pieces of one refinement never join)
    holds = [set() if source[s] < 0 else {int(source[s])} for s in range(n)]
    while True:
        ga, gb = group[ea], group[eb]
        cross = ga != gb
        if not cross.any():
            return group
        gbound = np.bincount(group, weights=boundary, minlength=n)
        lo, hi = np.minimum(ga, gb)[cross], np.maximum(ga, gb)[cross]
        keys, inv = np.unique(lo * n + hi, return_inverse=True)
        face = np.bincount(inv.ravel(), weights=el[cross])
        pa, pb = keys // n, keys % n
        ratio = face / np.maximum(np.minimum(gbound[pa], gbound[pb]), 1e-12)
        allowed = np.array([not (holds[a] & holds[b]) for a, b in zip(pa.tolist(), pb.tolist())], dtype=bool)
        cand = np.flatnonzero(allowed & (ratio >= r.min_open_ratio))
        if not len(cand):
            return group
        j = cand[np.lexsort((keys[cand], -ratio[cand]))[0]]
        a, b = int(pa[j]), int(pb[j])
        group[group == b] = a
        holds[a] |= holds[b]
