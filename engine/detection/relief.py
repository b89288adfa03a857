"""A beam stands out from the ceiling: beside it and below it there is air (issue 25 item 5).

The detector's beams are the windows that look like our training beams: a strip of points under the ceiling.  A
strip of the ceiling itself, where the ceiling is scanned thicker, sparser or noisier than in our generator, looks
the same to it, and so does the top of a wall: on our hard generated buildings 115-154 beams were kept per
building, 23 in one room, for 0-12 true ones, and on f707h (measured only) 244 for 9.

What a strip of ceiling lacks is relief.  A beam's box holds its underside and its sides; the box of the same size
beside it, across its thinner horizontal axis, holds air at that height (the ceiling above it aside), and so does the
box under it.  A strip of ceiling has the same points on both sides; a wall's top has the wall below it.  So, over
the lower three quarters of each box (the top quarter may hold the ceiling, beside the box as much as in it), a
detection of ``relief-classes`` is kept only if it holds at least ``relief-ratio`` times the points of the *emptier*
of its two side boxes (a beam may run beside a wall or a column on one side) and of the box below it (as deep as
three quarters of it).  The neighbour boxes stand ``relief-gap`` metres off the box: a fitted box's faces lie on the
beam's surfaces, and the scanner's noise puts half of a face's points beyond them.  A side box outside the space
holds no point.  Measurements:
``docs/experiments/detection.md``, "A beam stands out from the ceiling".
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from tiles.classes import ELEMENT_CLASSES

#: The share of a box's height, from its bottom, whose points are counted (the top quarter may hold the ceiling).
LOWER = 0.75


def count_in(points_in: Callable[[np.ndarray, np.ndarray], np.ndarray], lo: np.ndarray, hi: np.ndarray) -> int:
    """The number of points in the metric box ``[lo, hi)`` (``points_in``: a superset of them, as
    :meth:`engine.detection.pointindex.PointIndex.points_in_metric`)."""
    p = points_in(lo, hi)
    return int(np.all((p >= lo) & (p < hi), axis=1).sum()) if len(p) else 0


def relief(lo: np.ndarray, hi: np.ndarray, points_in: Callable[[np.ndarray, np.ndarray], np.ndarray],
           gap: float = 0.05) -> float:
    """How far a box ``[lo, hi)`` (canonical metres) stands out: the points of its lower :data:`LOWER` over one
    plus the most of the emptier side box's and the box below's (same size, the below box :data:`LOWER` deep; both
    ``gap`` metres off the box)."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    size = hi - lo
    top = lo[2] + LOWER * size[2]
    box_lo, box_hi = lo.copy(), np.array([hi[0], hi[1], top])
    inside = count_in(points_in, box_lo, box_hi)
    across = 0 if size[0] < size[1] else 1
    step = np.zeros(3)
    step[across] = size[across] + gap
    sides = min(count_in(points_in, box_lo - step, box_hi - step), count_in(points_in, box_lo + step, box_hi + step))
    below = count_in(points_in, np.array([lo[0], lo[1], lo[2] - gap - LOWER * size[2]]), np.array([hi[0], hi[1], lo[2] - gap]))
    return inside / (max(sides, below) + 1.0)


def flat(class_code: np.ndarray, lo_m: np.ndarray, hi_m: np.ndarray,
         points_in: Callable[[np.ndarray, np.ndarray], np.ndarray], classes: tuple[str, ...], ratio: float,
         gap: float = 0.05) -> np.ndarray:
    """Which detections of ``classes`` do not stand out (:func:`relief` under ``ratio``): those to drop."""
    codes = [ELEMENT_CLASSES.index(c) for c in classes]
    out = np.zeros(len(class_code), dtype=bool)
    for i in np.nonzero(np.isin(np.asarray(class_code), codes))[0]:
        out[i] = relief(lo_m[i], hi_m[i], points_in, gap) < ratio
    return out
