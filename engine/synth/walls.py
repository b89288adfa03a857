"""The walls of a floor on the cells' grid lines, and the thickness of each wall line.

A wall stands where cells of different spaces meet (or a cell meets the
outside); one thickness is drawn per wall line (interior 0.1-0.22 m,
exterior the building's own), partial walls 0.1-0.15 m.
"""
from __future__ import annotations

from collections import defaultdict

import numpy as np

from engine.synth import shapes
from engine.synth.building import Space, Wall
from engine.synth.layout import Draft


def thickness_draw(rng: np.random.Generator):
    """Interior wall thickness per wall line (0.1-0.22 m; partial walls 0.1-0.15 m), drawn once per line."""
    drawn: dict = {}

    def draw(key) -> float:
        if key not in drawn:
            lo, hi = (0.1, 0.15) if key[0] == "partial" else (0.1, 0.22)
            drawn[key] = round(float(rng.uniform(lo, hi)), 3)
        return drawn[key]
    return draw


def grid_walls(drafts: dict[int, Draft], floor: int, z: float, spaces: list[Space], rng: np.random.Generator,
           ext_t: float, first_id: int, length: float, depth: float) -> list[Wall]:
    """Walls where cells of different spaces meet (or a cell meets the outside), plus partial walls."""
    cells = [(c, sid) for sid, d in drafts.items() for c in d.cells]
    lines: dict[tuple[int, float], dict[str, list]] = defaultdict(lambda: {"lo": [], "hi": []})
    for (x0, y0, x1, y1), sid in cells:
        # horizontal lines (axis 1 = constant y): the cell is above its bottom line, below its top line
        lines[(1, round(y0, 6))]["hi"].append((x0, x1, sid))
        lines[(1, round(y1, 6))]["lo"].append((x0, x1, sid))
        lines[(0, round(x0, 6))]["hi"].append((y0, y1, sid))
        lines[(0, round(x1, 6))]["lo"].append((y0, y1, sid))
    thickness: dict[tuple[int, float], float] = {}
    raw: list[tuple[tuple[float, float], tuple[float, float], int, int, float, str]] = []
    for key in sorted(lines):
        axis, c = key
        lo, hi = lines[key]["lo"], lines[key]["hi"]
        breaks = sorted({v for a, b, _ in lo + hi for v in (a, b)})
        segs: list[list] = []
        for a, b in zip(breaks[:-1], breaks[1:]):
            m = (a + b) / 2
            below = next((s for p, q, s in lo if p < m < q), -1)
            above = next((s for p, q, s in hi if p < m < q), -1)
            if below == above:
                continue
            if segs and segs[-1][1] == a and segs[-1][2:] == [below, above]:
                segs[-1][1] = b
            else:
                segs.append([a, b, below, above])
        for a, b, below, above in segs:
            exterior = below == -1 or above == -1
            if exterior:
                t = ext_t
            else:
                if key not in thickness:
                    thickness[key] = round(float(rng.uniform(0.1, 0.22)), 3)
                t = thickness[key]
            if axis == 1:  # along +x: left (+y) is above
                raw.append(((a, c), (b, c), above, below, t, "exterior" if exterior else "interior"))
            else:  # along +y: left (-x) is the cell whose right side is on the line
                raw.append(((c, a), (c, b), below, above, t, "exterior" if exterior else "interior"))
    for sid, d in drafts.items():
        for p, q in d.partials:
            raw.append((p, q, sid, sid, round(float(rng.uniform(0.1, 0.15)), 3), "partial"))
    walls = []
    for k, (p0, p1, left, right, t, kind) in enumerate(raw):
        zs = [spaces[s].z1 for s in (left, right) if s >= 0]
        walls.append(Wall(first_id + k, floor, (float(p0[0]), float(p0[1])), (float(p1[0]), float(p1[1])),
                          float(t), z, max(zs), left, right, kind))
    shapes.joint_reach(walls)
    return walls
