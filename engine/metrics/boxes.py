"""3D boxes of the evaluation: arrays of box records, exact 3D IoU of yawed boxes, their world bounds.

Boxes are ``[cx, cy, cz, dx, dy, dz, yaw]``; the intersection of two is the intersection of their rotated
footprints times their overlap in z (:func:`box_iou_3d`).
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

#: Relative yaws closer than this (radians) to a multiple of 90 degrees are treated as exactly aligned.
YAW_TOL = 1e-9


def boxes_array(records: Sequence[dict[str, Any]]) -> np.ndarray:
    """``(n, 7)`` array ``[cx, cy, cz, dx, dy, dz, yaw]`` of box records (``center``, ``size``, ``yaw``)."""
    out = np.zeros((len(records), 7), dtype=np.float64)
    for i, r in enumerate(records):
        out[i, :3] = r["center"]
        out[i, 3:6] = r["size"]
        out[i, 6] = r.get("yaw", 0.0)
    return out


def corners_2d(box: np.ndarray) -> np.ndarray:
    """Footprint corners (4, 2) of one box ``[cx, cy, cz, dx, dy, dz, yaw]``, counter-clockwise."""
    cx, cy, _, dx, dy, _, yaw = box
    c, s = np.cos(yaw), np.sin(yaw)
    local = np.array([[-dx, -dy], [dx, -dy], [dx, dy], [-dx, dy]]) / 2.0
    return local @ np.array([[c, s], [-s, c]]) + [cx, cy]


def long_axis(size: Sequence[float], yaw: float) -> tuple[np.ndarray, float]:
    """The unit vector (x, y) along a box's longer horizontal side, and that side's length."""
    along = 0 if size[0] >= size[1] else 1
    c, s = float(np.cos(yaw)), float(np.sin(yaw))
    return (np.array([c, s]) if along == 0 else np.array([-s, c])), float(size[along])


def _clip_area(subject: np.ndarray, clip: np.ndarray) -> float:
    """Area of the intersection of two convex counter-clockwise polygons (Sutherland-Hodgman)."""
    poly = list(map(tuple, subject))
    m = len(clip)
    for i in range(m):
        if not poly:
            return 0.0
        ax, ay = clip[i]
        bx, by = clip[(i + 1) % m]
        ex, ey = bx - ax, by - ay

        def side(p):
            return ex * (p[1] - ay) - ey * (p[0] - ax)

        out = []
        for j in range(len(poly)):
            p, q = poly[j], poly[(j + 1) % len(poly)]
            sp, sq = side(p), side(q)
            if sp >= 0:
                out.append(p)
            if (sp >= 0) != (sq >= 0):
                t = sp / (sp - sq)
                out.append((p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])))
        poly = out
    if len(poly) < 3:
        return 0.0
    xy = np.asarray(poly)
    x, y = xy[:, 0], xy[:, 1]
    return float(abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) / 2.0)


def box_iou_3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact 3D IoU of every box of ``a`` ``(n, 7)`` with every box of ``b`` ``(m, 7)``: ``(n, m)``.

    Boxes are ``[cx, cy, cz, dx, dy, dz, yaw]``.  The intersection volume is the
    intersection area of the two rotated footprints times the overlap in z.
    Pairs whose relative yaw is a multiple of 90 degrees (the common case: both
    boxes in one Manhattan frame) are intersected as axis-aligned rectangles in
    that frame, vectorised; other pairs are clipped as polygons (Sutherland-Hodgman).
    """
    a = np.asarray(a, dtype=np.float64).reshape(-1, 7)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 7)
    n, m = len(a), len(b)
    out = np.zeros((n, m))
    if n == 0 or m == 0:
        return out
    # z overlap
    za0, za1 = a[:, 2] - a[:, 5] / 2, a[:, 2] + a[:, 5] / 2
    zb0, zb1 = b[:, 2] - b[:, 5] / 2, b[:, 2] + b[:, 5] / 2
    dz = np.clip(np.minimum(za1[:, None], zb1[None]) - np.maximum(za0[:, None], zb0[None]), 0, None)
    # footprint overlap: quick reject by circumscribed circles
    ra = np.hypot(a[:, 3], a[:, 4]) / 2
    rb = np.hypot(b[:, 3], b[:, 4]) / 2
    dist = np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1])
    cand = (dz > 0) & (dist < ra[:, None] + rb[None])
    rel = b[None, :, 6] - a[:, None, 6]
    quarter = np.round(rel / (np.pi / 2))
    aligned = np.abs(rel - quarter * np.pi / 2) <= YAW_TOL
    area = np.zeros((n, m))
    # aligned pairs: b's footprint in a's frame is an axis-aligned rectangle
    ii, jj = np.nonzero(cand & aligned)
    if len(ii):
        yaw = a[ii, 6]
        c, s = np.cos(yaw), np.sin(yaw)
        rx = b[jj, 0] - a[ii, 0]
        ry = b[jj, 1] - a[ii, 1]
        bx = c * rx + s * ry  # b's centre in a's frame
        by = -s * rx + c * ry
        odd = (quarter[ii, jj].astype(np.int64) % 2) == 1
        bdx = np.where(odd, b[jj, 4], b[jj, 3])
        bdy = np.where(odd, b[jj, 3], b[jj, 4])
        ox = np.minimum(a[ii, 3] / 2, bx + bdx / 2) - np.maximum(-a[ii, 3] / 2, bx - bdx / 2)
        oy = np.minimum(a[ii, 4] / 2, by + bdy / 2) - np.maximum(-a[ii, 4] / 2, by - bdy / 2)
        area[ii, jj] = np.clip(ox, 0, None) * np.clip(oy, 0, None)
    for i, j in zip(*np.nonzero(cand & ~aligned)):
        area[i, j] = _clip_area(corners_2d(a[i]), corners_2d(b[j]))
    inter = area * dz
    va = a[:, 3] * a[:, 4] * a[:, 5]
    vb = b[:, 3] * b[:, 4] * b[:, 5]
    union = va[:, None] + vb[None] - inter
    np.divide(inter, union, out=out, where=union > 0)
    return out



def aabb(boxes: np.ndarray) -> np.ndarray:
    """World axis-aligned bounds ``(n, 6)`` [min xyz, max xyz] of yawed boxes."""
    c, s = np.abs(np.cos(boxes[:, 6])), np.abs(np.sin(boxes[:, 6]))
    hx = (c * boxes[:, 3] + s * boxes[:, 4]) / 2
    hy = (s * boxes[:, 3] + c * boxes[:, 4]) / 2
    h = np.stack([hx, hy, boxes[:, 5] / 2], axis=1)
    return np.concatenate([boxes[:, :3] - h, boxes[:, :3] + h], axis=1)
