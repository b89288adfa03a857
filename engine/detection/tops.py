"""The top of a solid element fitted to its points: a bookcase is as tall as its points, not as the training ones.

A detection's height comes from its window and the learned box fit, both learnt from the training buildings'
bookcases; a bookcase of another catalogue (1.9-2.3 m where ours are about 1.8 m) keeps its bottom on the floor
and gets a top tens of centimetres too low, which caps its IoU near 0.5.  Its points show where it ends: above
the middle of its box, in each :data:`CELL` column of its footprint, they run without a gap of :data:`GAP` from
shelf to shelf up to its top board, and then stop, below the ceiling.  A column whose run goes on to the limit is
a wall behind or beside it (or a shelf up to the ceiling) and says nothing.  The top becomes the highest end of
the other columns' runs, looked for up to ``top-reach`` metres above the box (or lower, when the runs stop below
the box's top); no such column leaves the box as it is.  Settings: ``buildingparser.detection.top-*``.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from tiles.classes import ELEMENT_CLASSES

#: Side (metres) of the footprint's columns.
CELL = 0.1
#: The widest gap (metres) between two heights of one element's points (shelves are 0.25-0.4 m apart, and
#: their boards, books and the front edges of the sides fill the height between).
GAP = 0.1
#: Points a fit needs.
MIN_POINTS = 20


def run_tops(cell: np.ndarray, z: np.ndarray, start: float) -> dict[int, tuple[float, float]]:
    """Per column (``cell`` ids), the lowest point and the end of the run of its heights ``z`` (no gap over
    :data:`GAP`) that begins with it, of the points at or above ``start``."""
    keep = z >= start
    cell, z = cell[keep], z[keep]
    order = np.lexsort((z, cell))
    cell, z = cell[order], z[order]
    if not len(z):
        return {}
    first = np.r_[True, cell[1:] != cell[:-1]]
    breaks = np.r_[(np.diff(z) > GAP) | first[1:], True]  # the last point of a run
    starts = np.flatnonzero(first)
    ends = np.flatnonzero(breaks)
    ends = ends[np.searchsorted(ends, starts)]  # each column's first run ends there
    return {int(c): (float(a), float(b)) for c, a, b in zip(cell[starts], z[starts], z[ends])}


def fit_tops(lo_m: np.ndarray, hi_m: np.ndarray, class_code: np.ndarray,
             points_in_metric: Callable[[np.ndarray, np.ndarray], np.ndarray], classes: tuple[str, ...],
             reach: float, extent: np.ndarray) -> None:
    """Set in place the top (``hi_m[:, 2]``, canonical metres) of the detections of ``classes`` to the highest
    end of their columns' runs of points (see the module doc).

    ``points_in_metric(lo, hi)``: canonical points of the voxels a metric box touches; ``extent``: the space's
    size in canonical metres (its height bounds the search).
    """
    codes = [ELEMENT_CLASSES.index(c) for c in classes]
    for i in np.nonzero(np.isin(np.asarray(class_code), codes))[0]:
        mid = 0.5 * (lo_m[i, 2] + hi_m[i, 2])
        limit = min(hi_m[i, 2] + reach, float(extent[2]))
        flo, fhi = np.r_[lo_m[i, :2], mid], np.r_[hi_m[i, :2], limit]
        if np.any(fhi <= flo):
            continue
        p = points_in_metric(flo, fhi)
        p = p[np.all((p >= flo) & (p <= fhi), axis=1)]
        if len(p) < MIN_POINTS:
            continue
        ij = np.floor((p[:, :2] - flo[:2]) / CELL).astype(np.int64)
        runs = run_tops(ij[:, 0] * (1 << 20) + ij[:, 1], p[:, 2], mid)
        tops = [top for low, top in runs.values() if low <= mid + GAP and top < limit - GAP]
        if tops and max(tops) > mid + GAP:
            hi_m[i, 2] = max(tops)
