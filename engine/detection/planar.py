"""Boxes of planar elements on a wall fitted to their points along the wall's normal (issue 25 item 3).

A board (or any element of ``planar-classes``) is a plane a few centimetres in
front of a wall, sometimes with a ledge or tray.  Its ground-truth box is the
tightest box of its points: 1-4 cm deep for a bare board, as deep as its tray
for one with a tray.  A detection's box comes from the 10 cm voxel grid (and the
learned box fit) and is about a voxel deep whatever the element, which caps its
IoU with a 2 cm box far below 0.5.

Along the detection's thin horizontal axis the fit looks at two sets of points:
the wall *around* the element (the same heights, a strip beside each of its
ends) gives the wall's plane, the densest bin of their positions; the points
within the element's footprint from :data:`BEHIND` behind the plane to
``planar-depth`` metres in front of it, in runs separated by :data:`GAP` without
a point, hold the element: its face, edges and tray are one run, the first from
the back (a chair or a table in front is across a gap); the front is the side
facing the room, away from the space's nearer end.  The box runs from the
run's ``planar-quantile`` quantile (the wall's side, where the wall's own noise
mixes in) to its farthest point: the tightest box of the element's points, as
S3DIS's boxes are.  No wall beside the element (it fills the wall's width), too
few points, no point in front of the plane, or a run that goes on to
``planar-depth`` (a shelf's side or a corner's wall across the element's front:
the points do not show where it ends): the box is left as it is.
Settings: ``buildingparser.detection.planar-*``.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from tiles.classes import ELEMENT_CLASSES

#: Bin (metres) of the histogram of the wall's points whose densest bin is the wall's plane.
PLANE_BIN = 0.005
#: Points a fit needs: in the strips beside the element, and in front of the wall within its footprint.
MIN_POINTS = 20
#: How far behind the wall's plane (metres) an element's points may lie: scan noise and the edges of a board
#: seen at its back, never the wall's other face.
BEHIND = 0.03
#: A stretch along the normal (metres) without a point that ends the element: its face, edges and tray are
#: continuous in depth; a chair, a table or a sill in front of it is across such a gap.
GAP = 0.02
#: Cells of a wall's plane (metres): the least, and the most where the points are sparse (:func:`cell_side`).
CELL, MAX_CELL = 0.05, 0.2


def cell_side(count: int, area: float, per_cell: float) -> float:
    """The side (metres) of square cells of a wall's plane in which ``count`` points over ``area`` m² put
    ``per_cell`` points a cell on average: at least :data:`CELL`, at most :data:`MAX_CELL` (a sparse scan's cells
    are larger, so that they are not mostly empty); :data:`CELL` without points."""
    if count <= 0 or area <= 0.0:
        return CELL
    return float(np.clip(np.sqrt(per_cell * area / count), CELL, MAX_CELL))


def wall_plane(values: np.ndarray) -> float | None:
    """The position of the densest :data:`PLANE_BIN` bin of ``values`` (a wall's points along its normal),
    refined to the median of the points within a bin of it; None without :data:`MIN_POINTS` points."""
    if len(values) < MIN_POINTS:
        return None
    lo = float(values.min())
    h = np.bincount(((values - lo) / PLANE_BIN).astype(np.int64))
    peak = lo + (int(np.argmax(h)) + 0.5) * PLANE_BIN
    near = values[np.abs(values - peak) <= PLANE_BIN]
    return float(np.median(near))


def fit_depth(inside: np.ndarray, beside: np.ndarray, depth: float, quantile: float,
              side: float | None = None) -> tuple[float, float] | None:
    """The extent along the wall's normal of an element whose footprint holds the positions ``inside``, with
    the wall beside it at the positions ``beside``; None when the points do not show it (see the module doc).

    ``side``: +1 when the room (the element's front) lies towards larger positions, -1 towards smaller ones;
    None: the side holding more of the footprint's points.
    """
    plane = wall_plane(beside)
    if plane is None or len(inside) < MIN_POINTS:
        return None
    ahead = inside - plane
    if side is None:  # the element stands on the side where its footprint's points are
        side = 1.0 if np.count_nonzero((ahead > PLANE_BIN) & (ahead <= depth)) >= \
            np.count_nonzero((ahead < -PLANE_BIN) & (ahead >= -depth)) else -1.0
    front = side * ahead
    mine = front[(front >= -BEHIND) & (front <= depth)]
    if np.count_nonzero(mine > PLANE_BIN) < MIN_POINTS:
        return None
    run = element_run(mine)
    if run is None or run[-1] > depth - GAP:  # no run, or one that runs on: something crosses the element's front
        return None
    a, b = float(np.quantile(run, quantile)), float(run[-1])
    return (plane + a, plane + b) if side > 0 else (plane - b, plane - a)


def element_run(front: np.ndarray) -> np.ndarray | None:
    """The sorted positions of the first run of ``front`` (from the back) holding :data:`MIN_POINTS` points,
    runs being separated by :data:`GAP` without a point; None when no run holds that many."""
    v = np.sort(front)
    cuts = np.concatenate([[0], np.flatnonzero(np.diff(v) > GAP) + 1, [len(v)]])
    for s, e in zip(cuts[:-1], cuts[1:]):
        if e - s >= MIN_POINTS:
            return v[s:e]
    return None


def fit_planar(lo_m: np.ndarray, hi_m: np.ndarray, class_code: np.ndarray, points_in_metric: Any,
               classes: tuple[str, ...], depth: float, beside: float, quantile: float,
               extent: np.ndarray | None = None) -> int:
    """Fit in place the depth (``lo_m``, ``hi_m``: ``(n, 3)`` canonical metres) of the detections of ``classes``
    along their thinner horizontal axis; returns how many were fitted.

    ``points_in_metric(lo, hi)`` gives a superset of the canonical points of a metric box
    (:meth:`engine.detection.pointindex.PointIndex.points_in_metric`); ``beside`` is the width (metres) of the
    strips of wall looked at beside each end of the element.  With the space's ``extent`` (canonical metres) the
    element's wall is the one at the space's nearer end along that axis, its front faces the room (a board hangs
    on a wall that bounds its space); without it, the side holding more of the footprint's points.  The points
    cannot tell the side when the strips beside a detection narrower than its board hold the board's face: the
    face is then the densest plane, with as many points behind it as in front.
    """
    codes = [ELEMENT_CLASSES.index(c) for c in classes]
    done = 0
    for i in np.flatnonzero(np.isin(class_code, codes)):
        size = hi_m[i] - lo_m[i]
        a = 0 if size[0] <= size[1] else 1  # the normal: the thinner horizontal axis
        b = 1 - a
        centre = 0.5 * (lo_m[i, a] + hi_m[i, a])
        glo, ghi = lo_m[i].copy(), hi_m[i].copy()
        glo[a], ghi[a] = centre - depth - size[a], centre + depth + size[a]
        glo[b], ghi[b] = lo_m[i, b] - beside, hi_m[i, b] + beside
        pts = points_in_metric(glo, ghi)
        pts = pts[np.all((pts >= glo) & (pts <= ghi), axis=1)]
        within = (pts[:, b] >= lo_m[i, b]) & (pts[:, b] <= hi_m[i, b])
        side = None if extent is None else (1.0 if centre <= 0.5 * float(extent[a]) else -1.0)
        fit = fit_depth(pts[within, a], pts[~within, a], depth, quantile, side)
        if fit is not None:
            lo_m[i, a], hi_m[i, a] = fit
            done += 1
    return done


__all__ = ["element_run", "fit_depth", "fit_planar", "wall_plane"]
