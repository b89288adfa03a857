"""A room is closed by walls: a wall on every side of a space's box that holds one (issue 25 item 5).

The detector's walls are scored by what walls look like in the training buildings.  A wall unlike them (hidden by
cabinets, broken by a ribbon of windows, glass, a 30 cm wall seen from a room with a different finish) scores under
``score-threshold`` and is not proposed, or is proposed and re-ranked below 0, although a space's canonical box
ends at its walls: on f707h (measured only) 65 of 142 walls had no wall detection even at IoU 0.25, while a wall
window at the right place scored -0.4 to -1.5.

So, for the classes of ``side-classes``, the best window of the class at each of the four vertical sides of the
space's box (the canonical frame's ``x`` and ``y`` ends; :func:`side_of`: thin across the side, within
``side-reach`` metres of it) that scores above ``side-floor`` is a candidate (:func:`side_windows`).  After the box
fit and the re-ranking, a side where no detection of the class scores above 0 gets its best detection of the class
there, candidate or not (:func:`settle_sides`).  Such a detection is *sure*: the CRF keeps it whatever its score
(:data:`engine.detection.proposals.SURE`), as it keeps a space's ceiling and floor; its score stays the detector's, so it ranks
below the walls the detector believes, and the space update does not split or keep
spaces apart on it (``engine.spaces.update.wall_boxes``).  Measurements: ``docs/experiments/detection.md``, "A wall on every side".
"""
from __future__ import annotations

import numpy as np

from engine.detection.sliding import WindowScores

#: The four sides of a space's box: (horizontal axis, 0 at its low end / 1 at its high end).
SIDES = ((0, 0), (0, 1), (1, 0), (1, 1))


def side_of(lo: np.ndarray, hi: np.ndarray, shape: np.ndarray, thin: int, reach: np.ndarray) -> np.ndarray:
    """The side (index into :data:`SIDES`) each voxel box ``[lo, hi)`` lies at in a grid of ``shape`` voxels, or -1.

    A box lies at a side when it is at most ``thin`` voxels across it and longer along the side than across
    it, and its face towards the side is within ``reach`` voxels (per axis) of the grid's end there."""
    lo, hi = np.asarray(lo).reshape(-1, 3), np.asarray(hi).reshape(-1, 3)
    n, reach = np.asarray(shape), np.broadcast_to(np.asarray(reach), (3,))
    size = hi - lo
    out = np.full(len(lo), -1, dtype=np.int64)
    for s in range(len(SIDES) - 1, -1, -1):
        a, end = SIDES[s]
        thin_across = (size[:, a] <= thin) & (size[:, a] < size[:, 1 - a])
        near = lo[:, a] <= reach[a] if end == 0 else hi[:, a] >= n[a] - reach[a]
        out[thin_across & near] = s
    return out


def side_windows(ws: WindowScores, atom: int, grid_shape: np.ndarray, thin: int, reach: np.ndarray,
                 floor: float) -> tuple[np.ndarray, ...] | None:
    """One window shape's best position at each side of the space (:func:`side_of`) scoring above ``floor``.

    Returns ``(lo, hi, score, atom index per window)`` as :func:`engine.detection.candidates.top_windows`, or None."""
    shape = np.asarray(ws.shape)
    starts = (ws.px, ws.py, ws.pz)
    n, reach = np.asarray(grid_shape), np.broadcast_to(np.asarray(reach), (3,))
    found = []
    for a, end in SIDES:
        if not (shape[a] <= thin and shape[a] < shape[1 - a]):
            continue
        p = np.asarray(starts[a])
        at = np.nonzero(p <= reach[a] if end == 0 else p + shape[a] >= n[a] - reach[a])[0]
        if not len(at):
            continue
        sub = np.take(ws.scores, at, axis=a)
        if not sub.size:
            continue
        best = int(np.argmax(sub))
        if not np.isfinite(sub.flat[best]) or sub.flat[best] <= floor:
            continue
        idx = list(np.unravel_index(best, sub.shape))
        idx[a] = at[idx[a]]
        found.append(np.ravel_multi_index(tuple(idx), ws.scores.shape))
    if not found:
        return None
    flat = np.array(found, dtype=np.int64)
    lo, hi = ws.boxes(flat)
    return lo, hi, ws.scores.ravel()[flat], np.full(len(flat), atom)


def best_at_sides(lo: np.ndarray, hi: np.ndarray, score: np.ndarray, grid_shape: np.ndarray, thin: int,
                  reach: np.ndarray) -> np.ndarray:
    """Indices of the best-scoring box at each side (:func:`side_of`) that has any, in side order."""
    side = side_of(lo, hi, grid_shape, thin, reach)
    out = []
    for s in range(len(SIDES)):
        idx = np.nonzero(side == s)[0]
        if len(idx):
            out.append(int(idx[np.argmax(score[idx])]))
    return np.array(out, dtype=np.int64)


def settle_sides(lo: np.ndarray, hi: np.ndarray, score: np.ndarray, of_class: np.ndarray, candidate: np.ndarray,
                 grid_shape: np.ndarray, thin: int, reach: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which detections to keep and which are sure, once their final scores are known.

    ``of_class`` marks the detections of one side class, ``candidate`` those of them added as a side's best window
    (:func:`side_windows`).  At a side where a detection of the class that is no candidate scores above 0 (the
    detector believes a wall there), the candidates go.  At any other side, the best-scoring detection of the
    class there becomes sure, and the other candidates go.  Returns ``(keep, sure)`` masks."""
    keep = np.ones(len(score), dtype=bool)
    sure = np.zeros(len(score), dtype=bool)
    side = np.where(of_class, side_of(lo, hi, grid_shape, thin, reach), -1)
    for s in range(len(SIDES)):
        at = side == s
        if not at.any():
            continue
        if (at & ~candidate & (score > 0)).any():
            keep &= ~(at & candidate)
            continue
        idx = np.nonzero(at)[0]
        best = idx[np.argmax(score[idx])]
        sure[best] = True
        keep &= ~(at & candidate) | sure
    return keep, sure
