"""The scan tasks of a building: every space cut into slabs of a bounded estimated point count."""
from __future__ import annotations

import math

import numpy as np

from engine.synth.building import Building, PartSpec, Space
from engine.synth.geometry import Box


def plan_parts(b: Building, part_points: int) -> list[PartSpec]:
    """Cut every space whose estimated point count exceeds ``part_points`` into slabs; one task each."""
    parts: list[PartSpec] = []
    for s in b.spaces:
        est = estimate_points(s, b.density)
        n = max(1, math.ceil(est / max(part_points, 1)))
        fp = s.footprint
        ext = fp.max(0) - fp.min(0)
        axis = int(np.argmax(ext))
        lo, hi = float(fp[:, axis].min()), float(fp[:, axis].max())
        edges = np.linspace(lo, hi, n + 1)
        for k in range(n):
            a = -math.inf if k == 0 else float(edges[k])
            c = math.inf if k == n - 1 else float(edges[k + 1])
            parts.append(PartSpec(len(parts), s.id, k, n, axis, a, c, int(est / n)))
    return parts


def estimate_points(space: Space, density: float) -> float:
    """Upper bound of the points of a space (every surface fully seen) at ``density`` points per m^2."""
    total = 0.0
    for e in space.elements:
        for p in e.prims:
            if isinstance(p, Box):
                s = p.size
                total += 2 * (s[0] * s[1] + s[1] * s[2] + s[0] * s[2]) * p.density
            else:
                total += p.area * p.density
    return total * density * space.density
