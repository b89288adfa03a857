"""The building's orientations: each space detected in its group's frame, not in its own.

A space's own Manhattan yaw is the sharpest of its own points
(:func:`engine.detection.canonical.manhattan_yaw`).  In a real scan every room's
scan is registered with a small error of its own (a few hundredths to a few
tenths of a degree), and the estimate itself errs by as much in a room with few
or short walls; so the yaws of a building's rooms differ by that much, although
its walls were built parallel.  Ground truth is drawn in the building's frame
(S3DIS's boxes: the tightest box of an element's points in the building's axes;
the foreign buildings' the same), and so is a BIM model: a 10 m wall box 3 cm
thick turned by 0.25 degrees against that frame covers 7 cm of it, and meets the
wall's true box at IoU 0.4.

So detection first finds every space's own yaw, then groups them (modulo 90
degrees, neighbours within ``orientation-tolerance`` degrees); a group's yaw is
the median of its spaces' yaws, and each space within the tolerance of it is
detected in a frame of that yaw (:func:`reference_yaws`).  A wing built at an
angle is a group of its own.  Setting: ``buildingparser.detection.orientation-tolerance``
(degrees; 0: each space in its own frame, as before 2026-12-07).
"""
from __future__ import annotations

import numpy as np

QUARTER = np.pi / 2


def wrap_quarter(a: np.ndarray | float) -> np.ndarray:
    """Angles (radians) modulo 90 degrees, in ``[-45, 45)`` degrees."""
    return (np.asarray(a, dtype=np.float64) + QUARTER / 2) % QUARTER - QUARTER / 2


def reference_yaws(yaws: np.ndarray, tolerance: float) -> np.ndarray:
    """For each space's own yaw (radians), the yaw it is detected in: the median of its group's yaws (modulo 90
    degrees), or its own when it lies farther than ``tolerance`` (radians) from it.

    Groups: the yaws sorted around the quarter circle, cut where two neighbours are more than ``tolerance``
    apart (the circle opened at its widest gap).  Returns values in ``[-45, 45)`` degrees; a NaN (a space too
    small to have a yaw of its own) stays NaN and takes no part.
    """
    q = wrap_quarter(np.asarray(yaws, dtype=np.float64).reshape(-1))
    known = np.isfinite(q)
    if not known.all():
        out = q.copy()
        out[known] = reference_yaws(q[known], tolerance)
        return out
    if len(q) == 0 or tolerance <= 0:
        return q
    order = np.argsort(q, kind="stable")
    s = q[order]
    gaps = np.diff(np.append(s, s[0] + QUARTER))
    start = (int(np.argmax(gaps)) + 1) % len(s)  # the circle opened after its widest gap
    seq = np.roll(order, -start)
    v = np.roll(s, -start)
    v = np.where(np.arange(len(v)) >= len(v) - start, v + QUARTER, v) if start else v  # continuous around
    group = np.concatenate([[0], np.cumsum(np.diff(v) > tolerance)])
    ref = np.empty(len(q))
    for g in np.unique(group):
        mine = group == g
        med = float(np.median(v[mine]))
        ref[seq[mine]] = np.where(np.abs(v[mine] - med) <= tolerance, med, v[mine])
    return wrap_quarter(ref)
