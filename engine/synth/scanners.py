"""Scan positions of one space: about 5 m apart, clear of furniture, 1.35-1.65 m high."""
from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry import Point, Polygon

from engine.synth.building import Space
from engine.synth.geometry import Box


def place_scanners(rng: np.random.Generator, space: Space, spacing: float = 5.0) -> None:
    """Scan positions about ``spacing`` apart in every cell of the space, clear of furniture, 1.35-1.65 m high."""
    poly = Polygon(space.footprint)
    inner = poly.buffer(-0.4, join_style="mitre")
    if inner.is_empty:
        inner = poly
    boxes = [b for e in space.elements for b in e.prims if isinstance(b, Box)
             and b.center[2] - b.size[2] / 2 < space.z0 + 1.9]
    blocked = None
    if boxes:
        feet = shapely.polygons(np.array([b.corners()[[0, 2, 6, 4], :2] for b in boxes]))
        blocked = shapely.union_all(shapely.buffer(feet, 0.3, quad_segs=2))
    free = inner.difference(blocked) if blocked is not None else inner
    if free.is_empty:
        free = inner
    shapely.prepare(free)
    pts = []
    for cell in space.cells:
        region = shapely.box(*cell).intersection(poly)
        if region.is_empty:
            continue
        lo = np.array(region.bounds[:2])
        hi = np.array(region.bounds[2:])
        n = np.maximum(1, np.ceil((hi - lo) / spacing)).astype(int)
        for i in range(n[0]):
            for j in range(n[1]):
                target = lo + (hi - lo) * (np.array([i, j]) + 0.5) / n
                pt = _free_point(rng, free, target, region)
                if pt is not None:
                    pts.append(pt)
    if not pts:
        p = inner.representative_point()
        pts.append((p.x, p.y))
    z = space.z0 + rng.uniform(1.35, 1.65, len(pts))
    space.scanners = np.c_[np.asarray(pts, float), z]


def _free_point(rng, free, target, region) -> tuple[float, float] | None:
    for r in (0.0, 0.4, 0.8, 1.2, 1.6, 2.0):
        for _ in range(1 if r == 0 else 8):
            p = target + (rng.uniform(-r, r, 2) if r else 0.0)
            if shapely.contains_xy(free, p[0], p[1]) and region.buffer(0.5).contains(Point(*p)):
                return float(p[0]), float(p[1])
    return None
