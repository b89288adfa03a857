"""Baseline of paper Table 2: 2D Hough line fitting (after Xiao & Furukawa 2012) made into a space parser.

A storey's sample is projected on a density image (``pixel`` metres); walls
stack points over their height, so pixels at least ``wall_factor`` times the
median occupied pixel are wall candidates.  The probabilistic Hough transform
of scikit-image finds line segments in that mask (at least ``min_length``
long, gaps up to ``max_gap`` bridged); the segments become barriers
(:mod:`benchmarks.baselines.floorplan`).  Deterministic (seeded).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from benchmarks.baselines.floorplan import RasterParams, segment_storeys


@dataclass(frozen=True)
class HoughParams:
    pixel: float = 0.05
    wall_factor: float = 4.0
    threshold: int = 10
    min_length: float = 1.0
    max_gap: float = 0.25
    seed: int = 0


def detect_walls(xyz: np.ndarray, params: HoughParams | None = None) -> list[tuple[float, float, float, float]]:
    """Wall segments ``(x0, y0, x1, y1)`` of a storey's points by the probabilistic 2D Hough transform."""
    from skimage.transform import probabilistic_hough_line

    p = params or HoughParams()
    xy = np.asarray(xyz, dtype=np.float64)[:, :2]
    if len(xy) == 0:
        return []
    lo = xy.min(axis=0)
    ij = np.floor((xy - lo) / p.pixel).astype(np.int64)
    shape = (int(ij[:, 1].max()) + 1, int(ij[:, 0].max()) + 1)
    img = np.zeros(shape, dtype=np.int64)
    np.add.at(img, (ij[:, 1], ij[:, 0]), 1)
    med = float(np.median(img[img > 0]))
    mask = img >= max(p.wall_factor * med, 2)
    lines = probabilistic_hough_line(mask, threshold=p.threshold, line_length=int(round(p.min_length / p.pixel)),
                                     line_gap=int(round(p.max_gap / p.pixel)), rng=p.seed)
    out = []
    for (c0, r0), (c1, r1) in lines:
        x0, y0 = lo + (np.array([c0, r0]) + 0.5) * p.pixel
        x1, y1 = lo + (np.array([c1, r1]) + 0.5) * p.pixel
        out.append((float(x0), float(y0), float(x1), float(y1)))
    return out


def hough_spaces(store, client=None, params: HoughParams | None = None, raster: RasterParams | None = None) -> dict:
    """ARI of the 2D Hough baseline on a tile store with ``gt_space``."""
    return segment_storeys(store, lambda xyz: detect_walls(xyz, params), raster, client=client)
