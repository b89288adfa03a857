"""Scan-time difficulties (:mod:`engine.synth.hard.hardness`): flying points, reflections, registration errors.

Applied by :func:`engine.synth.scan.scan_job` to the points of one part, in
the building's local frame, after the noise and before the world transform,
all vectorised over the part's points:

1. **flying points** (mixed pixels): a point within 2.5 cm of the edge of a
   box face (furniture, columns, door leaves) or of a door or window opening
   in a wall lies on a depth discontinuity; with probability ``Space.flying``
   the sensor returns it somewhere along its ray behind the edge (pushed
   0.05-0.8 m away from the scan position that saw it).  Only points that stay
   inside the space (footprint, floor to ceiling) move; they become the
   space's flying-points instance (class clutter);
2. **reflections**: every window pane of the space mirrors the room: a point
   ``P`` seen as ``G``, its mirror image across the pane's plane, when the
   segment from the part's scan position to ``G`` crosses the pane, and only
   where ``G`` lies outside the floor's outline; a share ``Space.ghosts`` of
   them is kept, darker (``gt_space = gt_instance = -1``, class clutter);
3. **registration**: the points seen from scan position ``k`` move by its
   residual error (``Space.scan_jitter[k]``, about the position), then all by
   the space's error (``Space.registration``, about its centre).
"""
from __future__ import annotations

import numpy as np
import shapely

from engine.synth.building import Space
from engine.synth.geometry import Rect
from tiles.classes import CLASS_CODES

EDGE = 0.025
CLUTTER = CLASS_CODES["clutter"]


def _edge_distance(P: np.ndarray, rects: list[Rect], idx: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Distance (m) of each point to the border of its rectangle (box faces) or of its holes (wall faces)."""
    out = np.full(len(idx), np.inf)
    O = np.array([r.origin for r in rects], float)
    U = np.array([r.u for r in rects], float)
    V = np.array([r.v for r in rects], float)
    ul, vl = np.linalg.norm(U, axis=1), np.linalg.norm(V, axis=1)
    rel = P - O[idx]
    s = np.einsum("ij,ij->i", rel, U[idx]) / ul[idx]
    t = np.einsum("ij,ij->i", rel, V[idx]) / vl[idx]
    face = boxes[idx]
    out[face] = np.minimum.reduce([s[face], ul[idx][face] - s[face], t[face], vl[idx][face] - t[face]])
    holed = [k for k, r in enumerate(rects) if r.holes and not boxes[k]]
    for k in holed:
        sel = np.flatnonzero(idx == k)
        if not len(sel):
            continue
        for s0, s1, t0, t1 in rects[k].holes:
            ds = np.maximum.reduce([s0 - s[sel], s[sel] - s1, np.zeros(len(sel))])
            dt = np.maximum.reduce([t0 - t[sel], t[sel] - t1, np.zeros(len(sel))])
            out[sel] = np.minimum(out[sel], np.hypot(ds, dt))
    return out


def flying_points(rng: np.random.Generator, sp: Space, P: np.ndarray, S: np.ndarray, rects: list[Rect],
                  box_faces: np.ndarray, seen_from: np.ndarray) -> np.ndarray:
    """Move some points near depth edges along their rays (in place); returns the mask of those moved."""
    moved = np.zeros(len(P), bool)
    on_rect = np.flatnonzero(S < len(rects))
    if not len(on_rect) or sp.flying <= 0:
        return moved
    d = _edge_distance(P[on_rect], rects, S[on_rect], box_faces)
    cand = on_rect[(d < EDGE) & (rng.random(len(on_rect)) < sp.flying)]
    if not len(cand):
        return moved
    ray = P[cand] - seen_from[cand]
    ray /= np.maximum(np.linalg.norm(ray, axis=1), 1e-9)[:, None]
    Q = P[cand] + ray * rng.uniform(0.05, 0.8, len(cand))[:, None]
    inside = shapely.contains_xy(shapely.Polygon(sp.footprint), Q[:, 0], Q[:, 1])
    inside &= (Q[:, 2] > sp.z0 + 0.01) & (Q[:, 2] < sp.z1 - 0.01)
    P[cand[inside]] = Q[inside]
    moved[cand[inside]] = True
    return moved


def reflections(rng: np.random.Generator, sp: Space, P: np.ndarray, scanner: np.ndarray) -> np.ndarray:
    """Indices of the points whose mirror images in the space's window panes are kept, and the images."""
    if sp.ghosts <= 0 or not sp.mirrors or not len(P):
        return np.zeros(0, np.int64), np.zeros((0, 3))
    outline = shapely.Polygon(sp.outline) if sp.outline is not None else None
    idx, imgs = [], []
    for m in sp.mirrors:
        O, U, V = (np.asarray(a, float) for a in (m.origin, m.u, m.v))
        n = np.cross(U, V)
        n /= np.linalg.norm(n)
        take = np.flatnonzero(rng.random(len(P)) < sp.ghosts)
        if not len(take):
            continue
        G = P[take] - 2 * ((P[take] - O) @ n)[:, None] * n
        den = (G - scanner) @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = ((O - scanner) @ n) / den
        X = scanner + lam[:, None] * (G - scanner)
        a = (X - O) @ U / (U @ U)
        b = (X - O) @ V / (V @ V)
        ok = (lam > 0) & (lam < 1) & (a >= 0) & (a <= 1) & (b >= 0) & (b <= 1)
        if outline is not None and ok.any():
            ok[ok] = ~shapely.contains_xy(outline, G[ok, 0], G[ok, 1])
        idx.append(take[ok])
        imgs.append(G[ok])
    if not idx:
        return np.zeros(0, np.int64), np.zeros((0, 3))
    return np.concatenate(idx), np.concatenate(imgs)


def register(sp: Space, P: np.ndarray, seen_by: np.ndarray, scanners: np.ndarray, jitter: np.ndarray | None
             ) -> np.ndarray:
    """The points moved by the residual error of the scan position that saw each, then by the space's error."""
    if jitter is not None and len(jitter):
        k = np.clip(seen_by, 0, len(jitter) - 1)
        j = jitter[k]
        c, s = np.cos(j[:, 3]), np.sin(j[:, 3])
        rel = P[:, :2] - scanners[k, :2]
        P = P.copy()
        P[:, 0] = scanners[k, 0] + c * rel[:, 0] - s * rel[:, 1] + j[:, 0]
        P[:, 1] = scanners[k, 1] + s * rel[:, 0] + c * rel[:, 1] + j[:, 1]
        P[:, 2] += j[:, 2]
    return sp.registered(P)
