"""Furniture pieces and clutter objects, each a list of part boxes in its own frame.

A piece's frame has its origin at the centre of its footprint on the floor, x
across, y towards its back, z up.  Tables have a top and legs (the floor shows
between them), chairs a seat, a back and a base, bookcases sides, shelves and
books, sofas a base that hides the floor, boards hang on walls.  Clutter
(monitors, bins, plants, boxes, toilets...) is one object per instance, as in
S3DIS.  :class:`engine.synth.placer.Placer` turns and sets them down.
"""
from __future__ import annotations

import numpy as np

from engine.synth import colours as C

Part = tuple  # cx, cy, cz, sx, sy, sz, rgb[, turn about z in radians]


# -- pieces (local frames) -----------------------------------------------------------------
def table(rng: np.random.Generator, w: float, d: float, h: float, rgb: tuple) -> list[Part]:
    """A table or desk ``w`` x ``d``, top at ``h``: a top on four legs, or on side panels with a modesty panel."""
    top = 0.03
    parts: list[Part] = [(0, 0, h - top / 2, w, d, top, rgb)]
    if rng.random() < 0.6:
        leg = C.METAL if rng.random() < 0.5 else rgb
        for sx in (-1, 1):
            for sy in (-1, 1):
                parts.append((sx * (w / 2 - 0.05), sy * (d / 2 - 0.05), (h - top) / 2, 0.05, 0.05, h - top, leg))
    else:  # desk with side panels and a modesty panel
        for sx in (-1, 1):
            parts.append((sx * (w / 2 - 0.015), 0, (h - top) / 2, 0.03, d, h - top, rgb))
        parts.append((0, d / 2 - 0.06, h - top - 0.25, w - 0.06, 0.02, 0.35, rgb))
    return parts


def chair(rng: np.random.Generator, rgb: tuple) -> list[Part]:
    """An office chair (post and star base, maybe armrests) or a four-legged chair; back towards +y."""
    seat_z = rng.uniform(0.42, 0.5)
    parts: list[Part] = [(0, 0, seat_z, 0.46, 0.46, 0.07, rgb),
                         (0, 0.2, seat_z + 0.04 + 0.23, 0.44, 0.06, 0.46, rgb)]
    if rng.random() < 0.6:  # office chair: post and star base
        parts += [(0, 0, (0.07 + seat_z - 0.035) / 2, 0.05, 0.05, seat_z - 0.035 - 0.07, C.METAL),
                  (0, 0, 0.035, 0.56, 0.05, 0.07, C.METAL), (0, 0, 0.035, 0.05, 0.56, 0.07, C.METAL)]
        if rng.random() < 0.5:
            for sx in (-1, 1):
                parts.append((sx * 0.25, -0.02, seat_z + 0.22, 0.05, 0.3, 0.03, C.METAL))
                parts.append((sx * 0.25, 0.05, seat_z + 0.1, 0.03, 0.03, 0.2, C.METAL))
    else:  # four legs
        lz = seat_z - 0.035
        for sx in (-1, 1):
            for sy in (-1, 1):
                parts.append((sx * 0.2, sy * 0.2, lz / 2, 0.03, 0.03, lz, C.METAL))
    return parts


def sofa(rng: np.random.Generator, w: float, rgb: tuple) -> list[Part]:
    """A sofa ``w`` wide: a base on the floor (hiding it), cushions, back and arms."""
    d, h = rng.uniform(0.8, 0.95), rng.uniform(0.75, 0.9)
    return [(0, 0, 0.21, w, d, 0.42, rgb),
            (0, -0.08, 0.47, w - 0.36, d - 0.25, 0.1, rgb),
            (0, d / 2 - 0.1, 0.42 + (h - 0.42) / 2, w, 0.2, h - 0.42, rgb),
            (-(w / 2 - 0.09), 0, 0.52, 0.18, d, 0.2, rgb),
            (w / 2 - 0.09, 0, 0.52, 0.18, d, 0.2, rgb)]


def bookcase(rng: np.random.Generator, w: float, d: float, h: float, rgb: tuple) -> list[Part]:
    """Open shelves with books of random widths and colours, or a closed cabinet; back towards +y."""
    parts: list[Part] = []
    for sx in (-1, 1):
        parts.append((sx * (w / 2 - 0.01), 0, h / 2, 0.02, d, h, rgb))
    parts.append((0, d / 2 - 0.0075, h / 2, w - 0.04, 0.015, h, rgb))
    parts.append((0, -0.0075, h - 0.01, w - 0.04, d - 0.015, 0.02, rgb))
    parts.append((0, -0.0075, 0.04, w - 0.04, d - 0.015, 0.08, rgb))
    if rng.random() < 0.25:  # closed cabinet
        parts.append((0, -d / 2 + 0.01, h / 2 + 0.04, w - 0.04, 0.02, h - 0.1, rgb))
        return parts
    n = max(1, round((h - 0.1) / 0.36))
    levels = np.linspace(0.08, h - 0.02, n + 1)
    for z in levels[1:-1]:
        parts.append((0, -0.0075, z, w - 0.04, d - 0.04, 0.02, rgb))
    for a, b in zip(levels[:-1], levels[1:]):
        room = b - a - 0.03
        if room < 0.15 or rng.random() < 0.3:
            continue
        x = -w / 2 + 0.03
        while x < w / 2 - 0.1:
            bw = rng.uniform(0.08, 0.35)
            if x + bw > w / 2 - 0.03:
                break
            if rng.random() < 0.8:
                bh = rng.uniform(0.6, 0.95) * room
                parts.append((x + bw / 2, 0.01, a + 0.01 + bh / 2, bw, d - 0.08, bh, C.vivid(rng)))
            x += bw + 0.005
    return parts


def board(rng: np.random.Generator, w: float, h: float, bottom: float, rgb: tuple) -> list[Part]:
    """A thin board on a wall (back at +y) from ``bottom`` up, with a pen tray."""
    return [(0, 0.05 - 0.01, bottom + h / 2, w, 0.02, h, rgb),
            (0, 0.05 - 0.04, bottom - 0.01, 0.6 * w, 0.06, 0.02, C.METAL)]


def bare_board(w: float, h: float, bottom: float, rgb: tuple, thickness: float) -> list[Part]:
    """A bare board ``thickness`` thick on a wall, without a tray (``styles="varied"``)."""
    return [(0, 0.0, bottom + h / 2, w, thickness, h, rgb)]


def clutter(rng: np.random.Generator, kind: str, z: float = 0.0) -> tuple[list[Part], tuple[float, float]]:
    """A clutter object standing at height ``z``; also its footprint (w, d)."""
    rgb = C.vivid(rng)
    if kind == "monitor":
        sw = rng.uniform(0.45, 0.65)
        return [(0, 0.02, z + 0.01, 0.22, 0.18, 0.02, C.METAL), (0, 0.05, z + 0.08, 0.05, 0.04, 0.12, C.METAL),
                (0, 0.03, z + 0.14 + 0.17, sw, 0.04, 0.34, (25, 25, 28))], (sw, 0.2)
    if kind == "laptop":
        return [(0, 0, z + 0.01, 0.33, 0.23, 0.02, C.METAL), (0, 0.11, z + 0.12, 0.33, 0.01, 0.22, C.METAL)], (0.33, 0.24)
    if kind == "papers":
        w, d, h = rng.uniform(0.2, 0.35), rng.uniform(0.2, 0.3), rng.uniform(0.02, 0.15)
        return [(0, 0, z + h / 2, w, d, h, C.pick(rng, [(235, 235, 230), (220, 215, 190)]))], (w, d)
    if kind == "bin":
        return [(0, 0, z + 0.2, 0.3, 0.3, 0.4, rgb)], (0.3, 0.3)
    if kind == "box":
        s = rng.uniform(0.3, 0.6, 3)
        parts = [(0, 0, z + s[2] / 2, s[0], s[1], s[2], C.pick(rng, [(170, 130, 85), (190, 150, 100)]))]
        if rng.random() < 0.4:
            t = s * rng.uniform(0.6, 0.95, 3)
            parts.append((0, 0, z + s[2] + t[2] / 2, t[0], t[1], t[2], C.pick(rng, [(170, 130, 85)])))
        return parts, (s[0], s[1])
    if kind == "plant":
        p = rng.uniform(0.3, 0.45)
        f = rng.uniform(0.5, 0.8)
        fh = rng.uniform(0.6, 1.2)
        return [(0, 0, z + p / 2, p, p, p, rgb), (0, 0, z + p + fh / 2, f, f, fh, (50, 100, 45))], (f, f)
    if kind == "printer":
        return [(0, 0, z + 0.4, 0.5, 0.45, 0.35, (200, 200, 198)), (0, 0, z + 0.11, 0.45, 0.4, 0.22, C.METAL)], (0.5, 0.45)
    if kind == "cooler":
        return [(0, 0, z + 0.5, 0.32, 0.32, 1.0, (220, 220, 225)), (0, 0, z + 1.15, 0.26, 0.26, 0.3, (120, 160, 210))], \
            (0.32, 0.32)
    if kind == "toilet":
        return [(0, -0.05, z + 0.2, 0.38, 0.55, 0.4, (240, 240, 240)),
                (0, 0.22, z + 0.6, 0.4, 0.18, 0.4, (240, 240, 240))], (0.4, 0.7)
    raise ValueError(kind)
