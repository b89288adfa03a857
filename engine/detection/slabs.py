"""A floor's or a ceiling's extent across the room fitted to its own surface points (issue 25 item 3).

A space's floor (ceiling) window spans the space, so its box is as wide and as long as the space's points.
Where the space parsing left a few stray points of a neighbouring room in the space (clutter seen through a
glass partition or a door, flying pixels), the space is metres wider than its room and so is the floor's box,
while the ground truth's box is the tightest box of the floor's points: a 2 m hallway with a 2.7 m fringe gets a
floor box of IoU 0.4.  The floor's own points show where it ends: the points of its thin slab (the box's
height after the thin-surface refinement), projected on each horizontal axis of the space, fill :data:`BIN`
bins densely from one wall to the other (a beam meeting a ceiling, or a cabinet on a floor, leaves a gap, but
the bays beyond are as dense), while a neighbour's stray points are few in every bin they reach.  The box
becomes the tightest box of the slab's points from the first to the last dense bin (one holding at least
``slab-fraction`` of the count of the bin holding the median point) along both axes; it only ever shrinks.
Settings: ``buildingparser.detection.slab-*``.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from engine.detection.sparse import point_median
from tiles.classes import ELEMENT_CLASSES

#: Bin (metres) of the slab's profile along each horizontal axis.
BIN = 0.05
#: Points a fit needs.
MIN_POINTS = 100


def typical_count(h: np.ndarray) -> float:
    """The count of the bin that holds the median point of the histogram ``h``: the density of the bulk of the
    points, however many sparse bins a few stray points occupy."""
    c = np.asarray(h)[np.asarray(h) > 0]
    return point_median(c, c)


def dense_span(values: np.ndarray, lo: float, fraction: float) -> tuple[float, float]:
    """The span ``[a, b)`` (metres) from the first to the last :data:`BIN` bin of ``values`` (counted from
    ``lo``) that holds at least ``fraction`` times the :func:`typical_count`.

    The bins between may be sparse or empty: a ceiling's points stop where a beam meets it, a floor's under a
    cabinet; a neighbour's few stray points are sparse wherever they lie.
    """
    idx = np.floor((values - lo) / BIN).astype(np.int64)
    base = int(idx.min())
    h = np.bincount(idx - base)
    dense = np.flatnonzero(h >= fraction * typical_count(h))
    return lo + (base + dense[0]) * BIN, lo + (base + dense[-1] + 1) * BIN


def fit_slabs(lo_m: np.ndarray, hi_m: np.ndarray, class_code: np.ndarray,
              points_in_metric: Callable[[np.ndarray, np.ndarray], np.ndarray], classes: tuple[str, ...],
              fraction: float) -> int:
    """Shrink in place the horizontal extent (``lo_m``, ``hi_m``: ``(n, 3)`` canonical metres) of the detections
    of ``classes`` to the tightest box of their slab's points in its dense run (see the module doc); returns how
    many changed.

    ``points_in_metric(lo, hi)`` gives a superset of the canonical points of a metric box
    (:meth:`engine.detection.pointindex.PointIndex.points_in_metric`).
    """
    codes = [ELEMENT_CLASSES.index(c) for c in classes]
    done = 0
    for i in np.flatnonzero(np.isin(np.asarray(class_code), codes)):
        lo, hi = lo_m[i].copy(), hi_m[i].copy()
        p = points_in_metric(lo, hi)
        p = p[np.all((p >= lo) & (p <= hi), axis=1)]
        if len(p) < MIN_POINTS:
            continue
        keep = np.ones(len(p), dtype=bool)
        for a in (0, 1):
            x0, x1 = dense_span(p[:, a], float(lo[a]), fraction)
            keep &= (p[:, a] >= x0) & (p[:, a] < x1)
        if np.count_nonzero(keep) < MIN_POINTS:
            continue
        q = p[keep, :2]
        new_lo, new_hi = np.maximum(q.min(axis=0), lo[:2]), np.minimum(q.max(axis=0), hi[:2])
        if np.any(new_lo != lo[:2]) or np.any(new_hi != hi[:2]):
            lo_m[i, :2], hi_m[i, :2] = new_lo, new_hi
            done += 1
    return done


__all__ = ["dense_span", "fit_slabs", "typical_count"]
