"""The horizontal sides of a free-standing element fitted to its points, its base included.

A chair's box comes from a 10 cm grid and the learned box fit, both made on the training buildings' chairs: about
0.7 m square where a chair is 0.45-0.6 m, which caps its IoU near 0.5.  Its points show where it ends.  In the box
grown by ``footprint-grow`` metres on each horizontal side and down to the space's floor, the floor is the densest
:data:`BIN` of heights in the lowest :data:`FLOOR_BAND`; the points more than :data:`FLOOR_GAP` above it are the
element's and its neighbours'.  The element is their connected part (:data:`VOXEL` voxels) that holds most of
the box's, with the parts wholly above or below it centred over it (a star base under a seat whose gas column is
hidden): a table leg or a bin beside the chair that does not touch it is left out.  Along each horizontal axis a
side moves to the element's extreme but :data:`OUTLIERS` (a quantile would cut a star base's thin arms), but only
where it stops inside the grown box (no more than :data:`OUTLIERS` of its points within :data:`EDGE` of its
side): where it runs on to it, a neighbour touches the element (a table the chair is pushed under, a wall) and the
side stays.

Unlike the solid elements' rule (:mod:`engine.detection.reveal`, which leaves out the box's bottom voxel layer, the
floor's), the base near the floor counts: an office chair's star base spreads wider than its seat, and the
ground-truth box, the tightest box of the chair's points, holds it.  Runs after the scores (the re-ranking was
trained on the boxes before it).  Settings: ``buildingparser.detection.footprint-*``.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import ndimage

from tiles.classes import ELEMENT_CLASSES

#: Height bin (metres) of the floor's search.
BIN = 0.01
#: The floor is looked for in this many metres above the search's bottom.
FLOOR_BAND = 0.15
#: Points up to this many metres above the floor's bin are the floor's (scan noise).
FLOOR_GAP = 0.03
#: A side moves only where the points stop more than this many metres inside the grown box.
EDGE = 0.02
#: Points left out at each end of an axis (strays): a quantile would cut a star base's thin arms.
OUTLIERS = 5
#: Voxel (metres) of the connected parts: a neighbour nearer than about this touches the element.
VOXEL = 0.04
#: Points a fit needs.
MIN_POINTS = 20


def floor_level(z: np.ndarray, bottom: float) -> float | None:
    """The height of the densest :data:`BIN` of ``z`` within :data:`FLOOR_BAND` above ``bottom`` (its top
    edge), or None without points there."""
    low = z[z < bottom + FLOOR_BAND]
    if len(low) < MIN_POINTS:
        return None
    k = np.floor((low - bottom) / BIN).astype(np.int64)
    top = int(np.argmax(np.bincount(k)))
    return bottom + (top + 1) * BIN


def element_points(p: np.ndarray, origin: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The points ``p`` of the connected part (:data:`VOXEL` voxels from ``origin``, touching across edges and
    corners) that holds most of those in the box ``[lo, hi]``, with the parts :func:`stacked` on it: the element
    without the neighbours that do not touch it."""
    if len(p) == 0:
        return p
    ijk = np.floor((p - origin) / VOXEL).astype(np.int64)
    ijk -= ijk.min(axis=0)
    occupied = np.zeros(tuple(ijk.max(axis=0) + 1), dtype=bool)
    occupied[tuple(ijk.T)] = True
    labels, count = ndimage.label(occupied, structure=np.ones((3, 3, 3), dtype=bool))
    label = labels[tuple(ijk.T)]
    inside = np.all((p >= lo) & (p <= hi), axis=1)
    if count <= 1 or not inside.any():
        return p
    best = int(np.argmax(np.bincount(label[inside], minlength=count + 1)[1:])) + 1
    return p[np.isin(label, stacked(p, label, best, count))]


def stacked(p: np.ndarray, label: np.ndarray, best: int, count: int) -> np.ndarray:
    """The labels of part ``best`` and of the parts wholly above or below it whose centre lies over its horizontal
    extent (grown by a :data:`VOXEL`): a chair's star base under its seat, joined by a gas column too thin or too
    hidden to have points in every voxel."""
    idx = np.arange(1, count + 1)
    n = ndimage.sum_labels(np.ones(len(p)), label, idx)
    lo = np.column_stack([ndimage.minimum(p[:, a], label, idx) for a in range(3)])
    hi = np.column_stack([ndimage.maximum(p[:, a], label, idx) for a in range(3)])
    mid = np.column_stack([ndimage.sum_labels(p[:, a], label, idx) for a in range(2)]) / np.maximum(n, 1)[:, None]
    b = best - 1
    over = np.all((mid >= lo[b, :2] - VOXEL) & (mid <= hi[b, :2] + VOXEL), axis=1)
    apart = (hi[:, 2] < lo[b, 2]) | (lo[:, 2] > hi[b, 2])
    keep = (n > 0) & over & apart
    keep[b] = True
    return idx[keep]


def fit_footprints(lo_m: np.ndarray, hi_m: np.ndarray, class_code: np.ndarray,
                   points_in_metric: Callable[[np.ndarray, np.ndarray], np.ndarray], classes: tuple[str, ...],
                   grow: float, extent: np.ndarray) -> None:
    """Set in place the horizontal sides (canonical metres) of the detections of ``classes`` to where their
    points above the floor stop (see the module doc).  ``extent``: the space's size in canonical metres."""
    codes = [ELEMENT_CLASSES.index(c) for c in classes]
    ext = np.asarray(extent, dtype=np.float64)
    for i in np.nonzero(np.isin(np.asarray(class_code), codes))[0]:
        rlo, rhi = lo_m[i].copy(), hi_m[i].copy()
        rlo[:2], rhi[:2] = np.maximum(rlo[:2] - grow, 0.0), np.minimum(rhi[:2] + grow, ext[:2])
        rlo[2] = 0.0  # down to the space's floor, wherever the box's bottom is
        p = points_in_metric(rlo, rhi)
        p = p[np.all((p >= rlo) & (p <= rhi), axis=1)]
        floor = floor_level(p[:, 2], float(rlo[2])) if len(p) else None
        if floor is not None:
            p = p[p[:, 2] > floor + FLOOR_GAP]
        p = element_points(p, rlo, lo_m[i], hi_m[i])
        if len(p) < MIN_POINTS:
            continue
        for a in (0, 1):
            v = np.partition(p[:, a], (OUTLIERS, len(p) - 1 - OUTLIERS))
            qa, qb = float(v[OUTLIERS]), float(v[len(p) - 1 - OUTLIERS])
            a_lo = qa if np.count_nonzero(p[:, a] < rlo[a] + EDGE) <= OUTLIERS else lo_m[i, a]
            a_hi = qb if np.count_nonzero(p[:, a] > rhi[a] - EDGE) <= OUTLIERS else hi_m[i, a]
            if a_hi - a_lo > 2 * EDGE:
                lo_m[i, a], hi_m[i, a] = a_lo, a_hi
