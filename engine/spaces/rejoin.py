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

A face tested in another frame than one of its sides' spaces (a face of the building's frame beside a space a
wing's refinement parsed in the wing's frame) reads open where the wing's wall runs slanted across the building's
histograms (hr4101: a room and the wing's room beside it joined through 1.3 m of face, 0.065 of the room's
boundary), while a sliver that a wing's refinement cut off a room of the block shares a long side with it (about
half its boundary): such faces count only as a long side (``across_ratio``).
"""
from __future__ import annotations

import numpy as np

from engine.spaces.merging import Edge, MergeRules
from engine.spaces.slicing import Box


def rejoin_pieces(cells: list[Box], edges: list[Edge], labels: np.ndarray, sides: np.ndarray, source: np.ndarray,
                  bin_width: float, rules: MergeRules | None = None, across: np.ndarray | None = None,
                  across_ratio: float = 0.0) -> np.ndarray:
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
    across, across_ratio
        Per edge, whether it was tested in another frame than a side's space; such faces count toward a pair
        only where they make at least ``across_ratio`` of the smaller group's boundary (see the module doc).

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
    ex = np.zeros(len(edges), dtype=bool) if across is None else np.asarray(across, dtype=bool).reshape(-1)
    ex = ex[use]
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
        keys, ratio = _openness(ga[cross], gb[cross], el[cross], ex[cross], gbound, n, across_ratio)
        pa, pb = keys // n, keys % n
        allowed = np.array([not (holds[a] & holds[b]) for a, b in zip(pa.tolist(), pb.tolist())], dtype=bool)
        cand = np.flatnonzero(allowed & (ratio >= r.min_open_ratio))
        if not len(cand):
            return group
        j = cand[np.lexsort((keys[cand], -ratio[cand]))[0]]
        a, b = int(pa[j]), int(pb[j])
        group[group == b] = a
        holds[a] |= holds[b]


def _openness(ga: np.ndarray, gb: np.ndarray, length: np.ndarray, across: np.ndarray, gbound: np.ndarray, n: int,
              across_ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """Per pair of groups (key ``lo * n + hi``) with open faces between them: the faces' length over the smaller
    group's boundary, the faces tested in another frame counted only where they make ``across_ratio`` of it."""
    lo, hi = np.minimum(ga, gb), np.maximum(ga, gb)
    keys, inv = np.unique(lo * n + hi, return_inverse=True)
    inv = inv.ravel()
    smaller = np.maximum(np.minimum(gbound[keys // n], gbound[keys % n]), 1e-12)
    face = np.bincount(inv, weights=np.where(across, 0.0, length), minlength=len(keys))
    face_x = np.bincount(inv, weights=np.where(across, length, 0.0), minlength=len(keys))
    return keys, (face + np.where(face_x >= across_ratio * smaller, face_x, 0.0)) / smaller
