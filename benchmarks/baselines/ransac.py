"""Baseline of paper Table 2: RANSAC plane fitting (after Schnabel et al. 2007) made into a space parser.

Walls are vertical planes.  On a storey's sample without its floor and ceiling
(points within ``trim`` of the storey's lowest and highest), planes are found one after
another: each round draws ``iterations`` hypotheses (a vertical plane through
two random points), keeps the one with the most inliers within ``tolerance``,
refits it to its inliers (least squares), and removes them.  A plane is kept
as a wall when its inliers span at least ``min_height`` in z and it has at
least ``min_inliers`` of the sample's points; its inliers, projected on the
plane, are cut wherever they leave a gap of more than ``max_gap``, and each
run longer than ``min_length`` is a wall segment.  The segments become
barriers (:mod:`benchmarks.baselines.floorplan`).  Deterministic (seeded).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from benchmarks.baselines.floorplan import RasterParams, segment_storeys


@dataclass(frozen=True)
class RansacParams:
    tolerance: float = 0.02
    iterations: int = 400
    max_planes: int = 80
    min_inliers: float = 0.004  # of the storey's sample
    min_height: float = 1.5
    min_length: float = 0.8
    max_gap: float = 0.5
    #: Points within this of the storey's lowest and highest points (floor, ceiling) are left out.
    trim: float = 0.3
    #: Hypotheses are scored on a sample of this many points.
    score_points: int = 30_000
    seed: int = 0


def _segments_on_plane(xy: np.ndarray, origin: np.ndarray, direction: np.ndarray, p: RansacParams
                       ) -> list[tuple[float, float, float, float]]:
    t = np.sort((xy - origin) @ direction)
    if len(t) == 0:
        return []
    breaks = np.flatnonzero(np.diff(t) > p.max_gap)
    starts = np.r_[0, breaks + 1]
    stops = np.r_[breaks, len(t) - 1]
    out = []
    for a, b in zip(starts, stops):
        if t[b] - t[a] >= p.min_length:
            e0, e1 = origin + t[a] * direction, origin + t[b] * direction
            out.append((float(e0[0]), float(e0[1]), float(e1[0]), float(e1[1])))
    return out


def detect_walls(xyz: np.ndarray, params: RansacParams | None = None) -> list[tuple[float, float, float, float]]:
    """Wall segments ``(x0, y0, x1, y1)`` of a storey's points by sequential vertical-plane RANSAC."""
    p = params or RansacParams()
    rng = np.random.default_rng(p.seed)
    pts = np.asarray(xyz, dtype=np.float64)
    if len(pts):
        z0, z1 = np.quantile(pts[:, 2], [0.001, 0.999])
        pts = pts[(pts[:, 2] > z0 + p.trim) & (pts[:, 2] < z1 - p.trim)]
    need = max(50, int(p.min_inliers * len(pts)))
    segments: list[tuple[float, float, float, float]] = []
    remaining = np.arange(len(pts))
    for _ in range(p.max_planes):
        if len(remaining) < need:
            break
        xy = pts[remaining, :2]
        i = rng.integers(0, len(xy), p.iterations)
        j = rng.integers(0, len(xy), p.iterations)
        d = xy[j] - xy[i]
        norm = np.hypot(d[:, 0], d[:, 1])
        ok = norm > 0.2
        if not ok.any():
            break
        i, d, norm = i[ok], d[ok], norm[ok]
        normals = np.stack([-d[:, 1], d[:, 0]], axis=1) / norm[:, None]
        offsets = np.einsum("ij,ij->i", normals, xy[i])
        # inlier counts of all hypotheses on a sample, in chunks; then the best on all points
        sub = xy[rng.choice(len(xy), min(len(xy), p.score_points), replace=False)]
        best, best_count = -1, -1
        for k0 in range(0, len(normals), 64):
            dist = np.abs(sub @ normals[k0:k0 + 64].T - offsets[k0:k0 + 64])
            counts = (dist < p.tolerance).sum(axis=0)
            k = int(np.argmax(counts))
            if counts[k] > best_count:
                best, best_count = k0 + k, int(counts[k])
        inl = np.abs(xy @ normals[best] - offsets[best]) < p.tolerance
        if inl.sum() < need:
            break
        q = xy[inl]
        # least-squares refit of the line (principal direction of the inliers)
        c = q.mean(axis=0)
        _, _, vt = np.linalg.svd(q - c, full_matrices=False)
        direction = vt[0]
        normal = np.array([-direction[1], direction[0]])
        inl = np.abs((xy - c) @ normal) < p.tolerance
        z = pts[remaining[inl], 2]
        if len(z) and z.max() - z.min() >= p.min_height:
            segments += _segments_on_plane(xy[inl], c, direction, p)
        remaining = remaining[~inl]
    return segments


def ransac_spaces(store, client=None, params: RansacParams | None = None,
                  raster: RasterParams | None = None) -> dict:
    """ARI of the RANSAC baseline on a tile store with ``gt_space``."""
    return segment_storeys(store, lambda xyz: detect_walls(xyz, params), raster, client=client)
