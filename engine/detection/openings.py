"""The width and height of a window fitted to its opening in the wall's face.

A window detection's width and height are those of its sliding window, moved by the learned box fit: sizes of
the training buildings' windows.  Ribbon windows five metres wide, narrow full-height ones and windows of another
catalogue get a box of a training window's size at their place, which caps their IoU far below 0.5.  The wall
shows where the window is: its room-side face has points everywhere but in its openings, where the points (frame,
glass) lie deeper in the reveal.  Where the face is hidden (a desk under the window) there are no points at all,
which is no opening.

Along the detection's thin horizontal axis (the wall's normal) the face is the densest 1 cm bin of the points in
the box grown by :data:`DEPTH` metres, searched ``opening-grow`` metres beyond the box's sides and
:data:`VERTICAL` metres above and below it.  In a grid of cells of the wall's plane (5 cm, larger on a
sparse face: :func:`cell_size`), a cell with a
point within :data:`FACE` of the face is wall; one without, but with a point deeper than that (away from the
room), is open.  The connected open region that covers most of the detection's box is the opening, and the box
takes its width and height, side by side.  Where that region covers under :data:`MIN_SHARE` of the box, a narrower
window between piers is its opening (:func:`narrow_opening`: mostly inside the box, at least :data:`NARROW_SIDE`
wide and tall, :data:`PIER` metres of wall on each side); without one the box is left as it is.

A region that reaches the end of the search along the wall may be a ribbon window longer than the search: the
search then runs on along the wall, over the whole space, column of cells by column (:func:`run_along`), as long as
each column is a window's: open over at least half of the opening's height and, where the search reaches above or
below it, wall over at least half of those cells (a wall drifting off the face's plane is open above and below
too).  The ribbon's pieces that the detector found, each a training window's width, then make one detection:
of the followed detections whose fitted boxes overlap by more than ``nms-iou``, the best-scored, as the union of
their boxes along the wall and in height (:func:`one_per_opening`, called by :mod:`engine.detection.space`); the
detections not followed are left alone (a box fitted wrongly must not grow a good one).  A side still at the end
of the search (not the space's) keeps the box's.  Settings: ``buildingparser.detection.opening-*``.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import ndimage

from engine.detection.planar import cell_side
from engine.detection.sliding import box_iou
from tiles.classes import ELEMENT_CLASSES

#: Metres the box grows along the wall's normal, so that the wall's face is in it.
DEPTH = 0.1
#: Metres searched above and below the box.
VERTICAL = 0.6
#: Face points a cell of the wall's plane holds on average, at the least: a sparse scan's face would otherwise be
#: full of empty cells, and the glass of its openings mostly empty ones, which breaks an opening into specks.
CELL_POINTS = 4.0
#: A point within this many metres of the face's plane makes its cell wall.
FACE = 0.03
#: The least share of the detection's cells the opening covers.
MIN_SHARE = 0.3
#: Points a fit needs.
MIN_POINTS = 50
#: The least width and height (metres) of an opening narrower than its box.
NARROW_SIDE = 0.3
#: Metres of cells beside (above, below) a narrow opening whose columns (rows) must each be wall over half their
#: length: its piers, lintel and sill.
PIER = 0.15


def fit_openings(lo_m: np.ndarray, hi_m: np.ndarray, class_code: np.ndarray,
                 points_in_metric: Callable[[np.ndarray, np.ndarray], np.ndarray], classes: tuple[str, ...],
                 grow: float, extent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Set in place the width and height (canonical metres) of the detections of ``classes`` to their opening's
    (see the module doc); ``extent``: the space's size in canonical metres.  Returns whether each detection's
    opening was followed along the wall past the search (a ribbon's), and whether it was found with a sill (its
    bottom more than a cell above the space's floor: a window's, not a doorway's)."""
    codes = [ELEMENT_CLASSES.index(c) for c in classes]
    ext = np.asarray(extent, dtype=np.float64)
    followed = np.zeros(len(lo_m), dtype=bool)
    sill = np.zeros(len(lo_m), dtype=bool)
    for i in np.nonzero(np.isin(np.asarray(class_code), codes))[0]:
        a = 0 if hi_m[i, 0] - lo_m[i, 0] <= hi_m[i, 1] - lo_m[i, 1] else 1  # the wall's normal
        b = 1 - a
        rlo, rhi = lo_m[i].copy(), hi_m[i].copy()
        rlo[a], rhi[a] = rlo[a] - DEPTH, rhi[a] + DEPTH
        rlo[b], rhi[b] = rlo[b] - grow, rhi[b] + grow
        rlo[2], rhi[2] = rlo[2] - VERTICAL, rhi[2] + VERTICAL
        rlo, rhi = np.maximum(rlo, 0.0), np.minimum(rhi, ext)
        p = points_in_metric(rlo, rhi)
        p = p[np.all((p >= rlo) & (p <= rhi), axis=1)]
        if len(p) < MIN_POINTS:
            continue
        behind = -1 if 0.5 * (lo_m[i, a] + hi_m[i, a]) < 0.5 * ext[a] else 1  # the room is on the other side
        found = opening_box(p[:, a], behind, p[:, b], p[:, 2], (rlo[b], rhi[b]), (rlo[2], rhi[2]),
                            (lo_m[i, b], hi_m[i, b]), (lo_m[i, 2], hi_m[i, 2]), (0.0, ext[b]), (0.0, ext[2]))
        if found is None:
            continue
        (b0, b1), (z0, z1), face, runs, cell = found
        if runs[0] or runs[1]:  # a ribbon longer than the search: follow it along the wall
            wlo, whi = rlo.copy(), rhi.copy()
            wlo[b], whi[b] = 0.0, ext[b]
            w = points_in_metric(wlo, whi)
            w = w[np.all((w >= wlo) & (w <= whi), axis=1)]
            ends = run_along(w[:, a], behind, face, w[:, b], w[:, 2], (b0, b1), (z0, z1), (rlo[2], rhi[2]), runs,
                             ext[b], cell)
            followed[i] = ends[0] < b0 or ends[1] > b1
            b0, b1 = ends
        lo_m[i, b], hi_m[i, b], lo_m[i, 2], hi_m[i, 2] = b0, b1, z0, z1
        sill[i] = z0 > cell
    return followed, sill


def cells(span: tuple[float, float], origin: float, n: int, cell: float) -> slice:
    """The ``cell`` cells from ``origin`` that ``span`` touches, within ``n`` cells (at least one)."""
    first = int(np.clip((span[0] - origin) // cell, 0, n - 1))
    return slice(first, int(np.clip(-(-(span[1] - origin) // cell), first + 1, n)))


def cell_size(on_face: np.ndarray, u: np.ndarray, z: np.ndarray, u_range: tuple[float, float],
              z_range: tuple[float, float], box_u: tuple[float, float], box_z: tuple[float, float]) -> float:
    """The side (metres) of the cells of the wall's plane (:func:`engine.detection.planar.cell_side`) in which
    the face's points put :data:`CELL_POINTS` in a cell on average.  The face's
    density is that of its points (``on_face``) beside the box, over the search's area beside the box (the box
    may hold the opening); over the whole search where the box fills it."""
    area = (u_range[1] - u_range[0]) * (z_range[1] - z_range[0])
    inside = max(0.0, min(box_u[1], u_range[1]) - max(box_u[0], u_range[0])) * \
        max(0.0, min(box_z[1], z_range[1]) - max(box_z[0], z_range[0]))
    beside = on_face & ~((u >= box_u[0]) & (u <= box_u[1]) & (z >= box_z[0]) & (z <= box_z[1]))
    if area - inside >= 0.25 * area:
        return cell_side(int(beside.sum()), area - inside, CELL_POINTS)
    return cell_side(int(on_face.sum()), area, CELL_POINTS)


def opening_box(depth: np.ndarray, behind: int, u: np.ndarray, z: np.ndarray, u_range: tuple[float, float],
                z_range: tuple[float, float], box_u: tuple[float, float], box_z: tuple[float, float],
                space_u: tuple[float, float], space_z: tuple[float, float]
                ) -> tuple[tuple[float, float], tuple[float, float], float, tuple[bool, bool], float] | None:
    """The opening's ``(u0, u1), (z0, z1)`` in the wall's plane (a side that reaches the search's edge, short of
    the space's, keeps the box's), the face's depth, whether its two ends along the wall run on so and the cell
    (:func:`cell_size`); or None.
    ``behind`` (-1 or +1): the direction of ``depth`` away from the room; the other arguments as
    :func:`fit_openings` finds them."""
    hist, edges = np.histogram(depth, bins=max(1, int(np.ceil((depth.max() - depth.min()) / 0.01))))
    k = int(np.argmax(hist))
    face = 0.5 * (edges[k] + edges[k + 1])
    cell = cell_size(np.abs(depth - face) <= FACE, u, z, u_range, z_range, box_u, box_z)
    nu = max(1, int(np.ceil((u_range[1] - u_range[0]) / cell)))
    nz = max(1, int(np.ceil((z_range[1] - z_range[0]) / cell)))
    wall, seen = face_cells(depth, behind, face, u, z, u_range[0], z_range[0], nu, nz, cell)
    labels, count = ndimage.label(open_cells(wall, seen))
    if count == 0:
        return None
    inside = labels[cells(box_u, u_range[0], nu, cell), cells(box_z, z_range[0], nz, cell)]
    hits = np.bincount(inside.ravel(), minlength=count + 1)
    hits[0] = 0
    best = int(np.argmax(hits))
    if best == 0 or hits[best] < MIN_SHARE * inside.size:
        best = narrow_opening(labels, count, hits, wall, cell)
        if best == 0:
            return None
    su, sz = ndimage.find_objects(labels)[best - 1]
    u0, u1 = u_range[0] + su.start * cell, u_range[0] + su.stop * cell
    z0, z1 = z_range[0] + sz.start * cell, z_range[0] + sz.stop * cell
    # a side at the edge of the search (not the space's) runs on: keep the box's there
    runs = (su.start == 0 and u_range[0] > space_u[0] + 1e-9, su.stop == nu and u_range[1] < space_u[1] - 1e-9)
    if runs[0]:
        u0 = box_u[0]
    if runs[1]:
        u1 = box_u[1]
    if sz.start == 0 and z_range[0] > space_z[0] + 1e-9:
        z0 = box_z[0]
    if sz.stop == nz and z_range[1] < space_z[1] - 1e-9:
        z1 = box_z[1]
    return (u0, u1), (z0, z1), face, runs, cell


def narrow_opening(labels: np.ndarray, count: int, hits: np.ndarray, wall: np.ndarray, cell: float) -> int:
    """The label of the opening narrower than a box that covers too little of it (:data:`MIN_SHARE`), or 0:
    the region with most cells in the box among those with at least half of their cells in it, at least
    :data:`NARROW_SIDE` wide and tall, and bounded by wall: the columns of cells (:data:`PIER` metres) on each
    side of it (its piers) and the rows above and below it (lintel and sill), each wall over at least half of its
    length (a piece of a wider opening cut off by a seam of stray points has the rest of the opening beyond the
    seam, not a wall).  ``cell``: the grid's cell (metres)."""
    size = np.bincount(labels.ravel(), minlength=count + 1)
    side = int(round(NARROW_SIDE / cell))
    pier = max(1, int(round(PIER / cell)))
    best, most = 0, 0
    for r, (su, sz) in enumerate(ndimage.find_objects(labels), start=1):
        if hits[r] < 0.5 * size[r] or hits[r] <= most or su.stop - su.start < side or sz.stop - sz.start < side:
            continue
        beside = (wall[max(0, su.start - pier):su.start, sz], wall[su.stop:su.stop + pier, sz],
                  wall[su, max(0, sz.start - pier):sz.start].T, wall[su, sz.stop:sz.stop + pier].T)
        if all(w.shape[0] == pier and (w.mean(axis=1) >= 0.5).all() for w in beside):
            best, most = r, hits[r]
    return best


def face_cells(depth: np.ndarray, behind: int, face: float, u: np.ndarray, z: np.ndarray, u_origin: float,
               z_origin: float, nu: int, nz: int, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Two ``(nu, nz)`` grids of ``cell`` cells from the origins: a point within :data:`FACE` of the face
    (wall), a point deeper than that, away from the room (seen in the reveal)."""
    iu = np.clip(((u - u_origin) / cell).astype(np.int64), 0, nu - 1)
    iz = np.clip(((z - z_origin) / cell).astype(np.int64), 0, nz - 1)
    near = np.abs(depth - face) <= FACE
    wall = np.zeros((nu, nz), dtype=bool)
    wall[iu[near], iz[near]] = True
    deeper = (face - depth if behind < 0 else depth - face) > FACE
    seen = np.zeros((nu, nz), dtype=bool)
    seen[iu[deeper], iz[deeper]] = True
    return wall, seen


def open_cells(wall: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """The open cells: seen in the reveal and not wall, with the gaps of one cell between them closed (glass
    returns fewer points than the face, so a sparse scan's opening is open cells among empty ones); a closed gap
    is never wall, and the closing reaches no further than the open cells around it (a hidden face stays
    closed)."""
    found = seen & ~wall
    return (found | ndimage.binary_closing(found, structure=np.ones((3, 3), dtype=bool))) & ~wall


def run_along(depth: np.ndarray, behind: int, face: float, u: np.ndarray, z: np.ndarray, found_u: tuple[float, float],
              found_z: tuple[float, float], z_range: tuple[float, float], runs: tuple[bool, bool],
              length: float, cell: float) -> tuple[float, float]:
    """The ends along the wall of an opening found over ``found_u`` x ``found_z`` (an end that ``runs`` on is the
    box's), followed from there column by column over the wall's points (``u`` from 0 to ``length``) while each
    column is open over half of ``found_z`` at least and, where ``z_range`` reaches beyond ``found_z``, wall over
    half of those cells at least; or to the wall's end.  ``cell``: the grid's cell (metres)."""
    nu = max(1, int(np.ceil(length / cell)))
    nz = max(1, int(np.ceil((z_range[1] - z_range[0]) / cell)))
    wall, seen = face_cells(depth, behind, face, u, z, 0.0, z_range[0], nu, nz, cell)
    zc = z_range[0] + (np.arange(nz) + 0.5) * cell
    band = (zc >= found_z[0]) & (zc <= found_z[1])
    open_share = open_cells(wall, seen)[:, band].mean(axis=1) if band.any() else np.zeros(nu)
    wall_share = wall[:, ~band].mean(axis=1) if (~band).any() else np.ones(nu)
    window = (open_share >= 0.5) & (wall_share >= 0.5)
    lo = int(np.clip(np.floor(found_u[0] / cell), 0, nu - 1))
    hi = int(np.clip(np.ceil(found_u[1] / cell), lo + 1, nu))  # columns [lo, hi)
    if runs[0]:
        while lo > 0 and window[lo - 1]:
            lo -= 1
    if runs[1]:
        while hi < nu and window[hi]:
            hi += 1
    return (lo * cell if runs[0] else found_u[0]), (min(hi * cell, length) if runs[1] else found_u[1])


def one_per_opening(lo_m: np.ndarray, hi_m: np.ndarray, score: np.ndarray, followed: np.ndarray,
                    iou: float) -> np.ndarray:
    """Keep mask: of the ``followed`` detections (:func:`fit_openings`: a ribbon's pieces, each fitted to its one
    opening) whose boxes overlap by more than ``iou`` with a better one, the best-scored one, which takes in place
    the union of their boxes along the wall and in height (each piece found the opening's height from its own
    stretch of the wall); every other detection is kept as it is."""
    keep = np.ones(len(score), dtype=bool)
    idx = np.nonzero(np.asarray(followed, dtype=bool))[0]
    alive = np.ones(len(idx), dtype=bool)
    for k in np.lexsort((idx, -np.asarray(score)[idx])):
        if not alive[k]:
            continue
        i = idx[k]
        group = alive & (box_iou(lo_m[i], hi_m[i], lo_m[idx], hi_m[idx])[0] > iou)
        group[k] = True
        a = 0 if hi_m[i, 0] - lo_m[i, 0] <= hi_m[i, 1] - lo_m[i, 1] else 1  # the wall's normal: the best's depth
        for ax in (1 - a, 2):
            lo_m[i, ax], hi_m[i, ax] = lo_m[idx[group], ax].min(), hi_m[idx[group], ax].max()
        alive &= ~group
        keep[idx[group]] = False
        keep[i] = True
    return keep
