"""The width and height of a planar element on a wall fitted to its face, proud of the wall (issue 25 item 3).

A board's box along the wall and up it is its sliding window's, moved by the learned box fit: the sizes of the
training buildings' boards.  A board 0.9 or 3.4 m wide gets a box of a training board's width at its place.  After
its depth is fitted (:mod:`engine.detection.planar`), its points show its extent: the face stands in front of the
wall's plane (the densest plane of the wall beside the element, :func:`engine.detection.planar.wall_plane`) by the
board's depth, the wall around it does not.

In a grid of cells of the wall's plane (:func:`engine.detection.planar.cell_side`: larger where the scan is sparse, so
that a cell holds :data:`CELL_POINTS` of the box's face points on average), searched ``face-grow`` metres beyond the box's sides and
:data:`VERTICAL` metres above and below it, a cell is the element's when most of its points (at least
:data:`MIN_CELL` of them) stand in front of the plane by more than half the element's typical depth (the median of
its box's points), and not beyond its box's front (a chair or a table in front is not the board).  The connected
cells that cover most of the box are the element; the box takes their width and height, side by side, unless they
reach the edge of the search there (the face runs on: a wall's jog, a cabinet).  Cells covering under
:data:`MIN_SHARE` of the box leave it as it is, and call it *bare*: a wall with nothing standing out of it, which
:mod:`engine.detection.space` does not keep as a board (a board on a stand, with no wall beside it, is not
bare).  Settings: ``buildingparser.detection.face-*``.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import ndimage

from engine.detection.planar import BEHIND, cell_side, wall_plane
from tiles.classes import ELEMENT_CLASSES

#: Points a cell is to hold on average, which sets its size in a sparse scan.
CELL_POINTS = 8
#: Metres searched above and below the box.
VERTICAL = 0.3
#: Width (metres) of the strips of wall beside the box whose densest plane is the wall's.
BESIDE = 0.3
#: Points a cell needs to be judged.
MIN_CELL = 3
#: The least share of the box's cells the face covers.
MIN_SHARE = 0.3
#: The least depth (metres) in front of the plane that makes a point the face's.
MIN_PROUD = 0.004


def face_cells(along: np.ndarray, up: np.ndarray, front: np.ndarray, proud: float, shape: tuple[int, int]) -> np.ndarray:
    """Which cells (``shape``, indices ``along`` x ``up``) hold at least :data:`MIN_CELL` points of which most
    stand in front of the wall by more than ``proud`` metres (``front``: each point's distance in front)."""
    flat = along * shape[1] + up
    n = np.bincount(flat, minlength=shape[0] * shape[1])
    ahead = np.bincount(flat, weights=(front > proud).astype(np.float64), minlength=shape[0] * shape[1])
    return ((n >= MIN_CELL) & (ahead > 0.5 * n)).reshape(shape)


def face_extent(cells: np.ndarray, box: tuple[slice, slice]) -> tuple[int, int, int, int] | None:
    """The cell bounds ``(a0, a1, u0, u1)`` (ends excluded) of the connected face cells covering most of the cells
    ``box``; None when they cover under :data:`MIN_SHARE` of it."""
    comp, n = ndimage.label(cells)
    if not n:
        return None
    inside = comp[box]
    counts = np.bincount(inside.ravel(), minlength=n + 1)[1:]
    best = int(np.argmax(counts)) + 1
    if counts[best - 1] < MIN_SHARE * inside.size:
        return None
    ia, iu = np.nonzero(comp == best)
    return int(ia.min()), int(ia.max()) + 1, int(iu.min()), int(iu.max()) + 1


def fit_faces(lo_m: np.ndarray, hi_m: np.ndarray, class_code: np.ndarray,
              points_in_metric: Callable[[np.ndarray, np.ndarray], np.ndarray], classes: tuple[str, ...],
              grow: float, extent: np.ndarray) -> tuple[int, np.ndarray]:
    """Set in place the width and height (canonical metres) of the detections of ``classes`` to their face's (see
    the module doc); ``extent``: the space's size in canonical metres.  Returns how many were fitted, and which
    are bare: a wall's plane beside them but no face standing out of it over their box."""
    codes = [ELEMENT_CLASSES.index(c) for c in classes]
    ext = np.asarray(extent, dtype=np.float64)
    done = 0
    bare = np.zeros(len(lo_m), dtype=bool)
    for i in np.flatnonzero(np.isin(np.asarray(class_code), codes)):
        a = 0 if hi_m[i, 0] - lo_m[i, 0] <= hi_m[i, 1] - lo_m[i, 1] else 1  # the wall's normal
        b = 1 - a
        side = 1.0 if 0.5 * (lo_m[i, a] + hi_m[i, a]) <= 0.5 * ext[a] else -1.0  # the room's side, as planar's
        rlo, rhi = lo_m[i].copy(), hi_m[i].copy()
        rlo[b], rhi[b] = rlo[b] - grow - BESIDE, rhi[b] + grow + BESIDE
        rlo[2], rhi[2] = rlo[2] - VERTICAL, rhi[2] + VERTICAL
        rlo[a], rhi[a] = rlo[a] - BEHIND, rhi[a] + BEHIND
        rlo, rhi = np.maximum(rlo, 0.0), np.minimum(rhi, ext)
        p = points_in_metric(rlo, rhi)
        p = p[np.all((p >= rlo) & (p <= rhi), axis=1)]
        at = (p[:, 2] >= lo_m[i, 2]) & (p[:, 2] <= hi_m[i, 2])
        beside = at & ((p[:, b] < lo_m[i, b] - grow) | (p[:, b] > hi_m[i, b] + grow))
        plane = wall_plane(p[beside, a])
        if plane is None:
            continue
        front = side * (p[:, a] - plane)
        reach = side * ((hi_m[i, a] if side > 0 else lo_m[i, a]) - plane)  # the box's front, from the plane
        inbox = at & (p[:, b] >= lo_m[i, b]) & (p[:, b] <= hi_m[i, b]) & (front > MIN_PROUD) & (front <= reach)
        if reach <= MIN_PROUD or np.count_nonzero(inbox) < MIN_CELL:
            bare[i] = True
            continue
        proud = max(0.5 * float(np.median(front[inbox])), MIN_PROUD)
        area = max((hi_m[i, b] - lo_m[i, b]) * (hi_m[i, 2] - lo_m[i, 2]), 1e-6)
        cell = cell_side(np.count_nonzero(inbox), area, CELL_POINTS)
        s_lo = np.array([lo_m[i, b] - grow, lo_m[i, 2] - VERTICAL])
        s_lo = np.maximum(s_lo, 0.0)
        s_hi = np.minimum([hi_m[i, b] + grow, hi_m[i, 2] + VERTICAL], [ext[b], ext[2]])
        shape = tuple(int(v) for v in np.maximum(np.ceil((s_hi - s_lo) / cell), 1))
        keep = (front >= -BEHIND) & (front <= reach) & (p[:, b] >= s_lo[0]) & (p[:, b] <= s_hi[0]) \
            & (p[:, 2] >= s_lo[1]) & (p[:, 2] <= s_hi[1])
        ia = np.minimum(((p[keep, b] - s_lo[0]) / cell).astype(np.int64), shape[0] - 1)
        iu = np.minimum(((p[keep, 2] - s_lo[1]) / cell).astype(np.int64), shape[1] - 1)
        cells = face_cells(ia, iu, front[keep], proud, shape)
        bl = np.floor((np.array([lo_m[i, b], lo_m[i, 2]]) - s_lo) / cell).astype(np.int64)
        bh = np.ceil((np.array([hi_m[i, b], hi_m[i, 2]]) - s_lo) / cell).astype(np.int64)
        bl, bh = np.clip(bl, 0, np.array(shape) - 1), np.clip(bh, 1, np.array(shape))
        found = face_extent(cells, (slice(bl[0], bh[0]), slice(bl[1], bh[1])))
        if found is None:
            bare[i] = True
            continue
        a0, a1, u0, u1 = found
        if a0 > 0:
            lo_m[i, b] = s_lo[0] + a0 * cell
        if a1 < shape[0]:
            hi_m[i, b] = s_lo[0] + a1 * cell
        if u0 > 0:
            lo_m[i, 2] = s_lo[1] + u0 * cell
        if u1 < shape[1]:
            hi_m[i, 2] = s_lo[1] + u1 * cell
        done += 1
    return done, bare


__all__ = ["face_cells", "face_extent", "fit_faces"]
