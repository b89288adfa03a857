"""Floor layouts: which space occupies which centre-line rectangle of a floor.

A floor is a rectangle ``L x D`` cut into *bands* along y: each band is a row
of rooms, a hallway, and a second row of rooms (a double-loaded corridor, the
commonest office plan).  Rows are cut into rooms 2-15 m wide; cross hallways
join the hallways of neighbouring bands; the ground floor gets a lobby at one
end; long hallways are cut into segments by fire-door walls.  Then some rooms
are reshaped: an *L-shaped* room takes the far half of its neighbour, an
*open-plan* space merges two or three rooms and keeps only partial walls
between them.  Finally the number of rooms is nudged (splitting the widest,
merging the narrowest pairs) towards a requested count.

The result is a list of :class:`Draft` spaces, each a set of axis-aligned
cells on the wall centre lines; :mod:`engine.synth.plan` turns it into walls,
openings and clear footprints.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: Room widths are drawn in this range (m) and never exceed ROOM_MAX.
ROOM_MIN, ROOM_MAX = 2.4, 15.0
CIRCULATION = ("hallway", "lobby")


@dataclass
class Draft:
    """A space of a floor layout: its type, cells ``(x0, y0, x1, y1)`` and partial walls ``((x, y), (x, y))``."""

    type: str
    cells: list[tuple[float, float, float, float]]
    partials: list[tuple[tuple[float, float], tuple[float, float]]] = field(default_factory=list)
    row: int = -1  # index of the row of rooms it came from (-1: hallway, lobby)
    simple: bool = True  # a plain one-cell room that may be split or merged
    #: Non-rectangular floors (:mod:`engine.synth.shapes`): the centre-line polygon in the floor's frame and
    #: the angle of the space's own frame, in which ``cells`` (and ``partials``) are then given.
    poly: Any = None
    axis: float = 0.0

    @property
    def area(self) -> float:
        if self.poly is not None:
            return float(self.poly.area)
        return sum((c[2] - c[0]) * (c[3] - c[1]) for c in self.cells)

    @property
    def width(self) -> float:
        return max(c[2] for c in self.cells) - min(c[0] for c in self.cells)


@dataclass
class Row:
    y0: float
    y1: float
    hall_side: int  # +1: the hallway is above (y1), -1: below (y0)


@dataclass
class FloorLayout:
    length: float
    depth: float
    drafts: list[Draft]
    rows: list[Row]


def floor_layout(rng: np.random.Generator, area: float, *, target: int | None = None, lobby: bool = True,
                 outline: tuple[float, float] | None = None) -> FloorLayout:
    """A layout of about ``area`` m^2 (centre-line rectangle) with ``target`` spaces if given.

    ``outline`` (length, depth) fixes the rectangle (upper floors of a building): the
    band depths drawn are then scaled to fill it.
    """
    length, depth, rows, halls = _bands(rng, area, outline)
    drafts: list[Draft] = []
    blocked: dict[int, list[tuple[float, float]]] = {i: [] for i in range(len(rows))}
    hall_x0 = {i: 0.0 for i in range(len(halls))}
    if lobby and length >= 20:
        hall_x0[0] = _lobby(rng, length, rows, halls, drafts, blocked)
    _cross_hallways(rng, length, rows, halls, drafts, blocked)
    _hallways(rng, length, halls, hall_x0, drafts)
    # rows of rooms between the blocked intervals
    for i, r in enumerate(rows):
        for a, b in _free_intervals(0.0, length, blocked[i]):
            for x0, x1 in _split_run(rng, a, b):
                drafts.append(Draft("room", [(x0, r.y0, x1, r.y1)], row=i))

    _reshape(rng, drafts, rows)
    if target is not None:
        _adjust_count(rng, drafts, target)
    return FloorLayout(length, depth, drafts, rows)


def _bands(rng: np.random.Generator, area: float, outline: tuple[float, float] | None
           ) -> tuple[float, float, list[Row], list[tuple[float, float]]]:
    """Length and depth of the floor, its rows of rooms and its hallways (y extents), band by band."""
    if outline is not None:
        area = outline[0] * outline[1]
    bands = max(1, round(math.sqrt(area / 560.0)))
    single = area < 110  # a single-loaded corridor: one row of rooms beside the hallway
    ys: list[tuple[str, float]] = []  # ("room" | "hall", depth) from y = 0 up
    for _ in range(bands):
        ys.append(("room", rng.uniform(4.0, 5.5) if single else rng.uniform(4.2, 7.5)))
        ys.append(("hall", rng.uniform(1.8, 2.8)))
        if not single:
            ys.append(("room", rng.uniform(4.2, 7.5)))
    depth = sum(d for _, d in ys)
    if outline is not None:
        ys = [(k, d * outline[1] / depth) for k, d in ys]
        depth = outline[1]
    length = round(max(area / depth, 6.0), 2) if outline is None else outline[0]
    # y extents
    rows: list[Row] = []
    halls: list[tuple[float, float]] = []
    y = 0.0
    for i, (kind, d) in enumerate(ys):
        y0, y1 = round(y, 3), round(y + d, 3)
        if kind == "hall":
            halls.append((y0, y1))
        else:
            above_is_hall = i + 1 < len(ys) and ys[i + 1][0] == "hall"
            rows.append(Row(y0, y1, 1 if above_is_hall else -1))
        y += d
    depth = round(y, 3) if outline is None else outline[1]
    return length, depth, rows, halls


def _lobby(rng: np.random.Generator, length: float, rows: list[Row], halls: list[tuple[float, float]],
           drafts: list[Draft], blocked: dict[int, list[tuple[float, float]]]) -> float:
    """The lobby: the first metres of band 0, its hallway and the rows beside it while it stays within 15 m deep.

    Returns where band 0's hallway starts (the lobby's end).
    """
    lb = round(float(rng.uniform(6.0, min(12.0, length / 3))), 2)
    band_rows = [i for i, r in enumerate(rows) if _band_of(r, halls) == 0]
    y0, y1 = halls[0]
    for i in sorted(band_rows, key=lambda i: rows[i].y1 - rows[i].y0):
        r = rows[i]
        if max(y1, r.y1) - min(y0, r.y0) <= 15.0:
            y0, y1 = min(y0, r.y0), max(y1, r.y1)
            blocked[i].append((0.0, lb))
    drafts.append(Draft("lobby", [(0.0, y0, lb, y1)], simple=False))
    return lb


def _cross_hallways(rng: np.random.Generator, length: float, rows: list[Row], halls: list[tuple[float, float]],
                    drafts: list[Draft], blocked: dict[int, list[tuple[float, float]]]) -> None:
    """Cross hallways between neighbouring bands."""
    for b in range(len(halls) - 1):
        lo_hall, hi_hall = halls[b], halls[b + 1]
        between = [i for i, r in enumerate(rows) if r.y0 >= lo_hall[1] - 1e-6 and r.y1 <= hi_hall[0] + 1e-6]
        n_cross = 1 if length < 60 else 2
        width = round(rng.uniform(1.8, 2.6), 2)
        for k in range(n_cross):
            lo = length * k / n_cross + 3.0
            hi = length * (k + 1) / n_cross - 3.0 - width
            x0 = round(float(rng.uniform(lo, max(lo, hi))), 2)
            drafts.append(Draft("hallway", [(x0, lo_hall[1], x0 + width, hi_hall[0])], simple=False))
            for i in between:
                blocked[i].append((x0, x0 + width))


def _hallways(rng: np.random.Generator, length: float, halls: list[tuple[float, float]], hall_x0: dict[int, float],
              drafts: list[Draft]) -> None:
    """The hallway of each band, cut by fire-door walls when long."""
    for b, (y0, y1) in enumerate(halls):
        x0 = hall_x0[b]
        run = length - x0
        n_seg = max(1, math.ceil(run / 38.0)) if run > 45 else 1
        cuts = np.linspace(x0, length, n_seg + 1)
        if n_seg > 1:
            cuts[1:-1] += rng.uniform(-3, 3, n_seg - 1)
        for a, c in zip(cuts[:-1], cuts[1:]):
            drafts.append(Draft("hallway", [(round(float(a), 3), y0, round(float(c), 3), y1)], simple=False))


def _band_of(row: Row, halls: list[tuple[float, float]]) -> int:
    for b, (y0, y1) in enumerate(halls):
        if abs(row.y1 - y0) < 1e-6 or abs(row.y0 - y1) < 1e-6:
            return b
    return -1


def _free_intervals(a: float, b: float, blocked: list[tuple[float, float]]) -> list[tuple[float, float]]:
    out, x = [], a
    for lo, hi in sorted(blocked):
        if lo > x + 1e-6:
            out.append((x, lo))
        x = max(x, hi)
    if b > x + 1e-6:
        out.append((x, b))
    return out


def _split_run(rng: np.random.Generator, a: float, b: float) -> list[tuple[float, float]]:
    """Cut ``[a, b]`` into room widths between ROOM_MIN and ROOM_MAX (mostly 3-7 m)."""
    length = b - a
    n = max(1, round(length / rng.uniform(4.0, 6.0)))
    while length / n > ROOM_MAX:
        n += 1
    while n > 1 and length / n < ROOM_MIN + 0.4:
        n -= 1
    for _ in range(50):
        w = np.where(rng.random(n) < 0.2, rng.uniform(7, 11, n), rng.uniform(2.8, 6.5, n))
        w = w * length / w.sum()
        if n == 1 or (w.min() >= ROOM_MIN and w.max() <= ROOM_MAX):
            break
    else:
        w = np.full(n, length / n)
    edges = a + np.r_[0.0, np.cumsum(w)]
    edges[-1] = b
    edges = np.round(edges, 3)
    return list(zip(edges[:-1].tolist(), edges[1:].tolist()))


def _neighbours_in_row(drafts: list[Draft]) -> list[tuple[int, int]]:
    """Pairs of simple rooms side by side in the same row (sharing a whole divider)."""
    simple = [(i, d.cells[0]) for i, d in enumerate(drafts) if d.simple and d.type == "room"]
    simple.sort(key=lambda t: (drafts[t[0]].row, t[1][0]))
    pairs = []
    for (i, a), (j, b) in zip(simple, simple[1:]):
        if drafts[i].row == drafts[j].row and abs(a[2] - b[0]) < 1e-6:
            pairs.append((i, j))
    return pairs


def _reshape(rng: np.random.Generator, drafts: list[Draft], rows: list[Row]) -> None:
    """Make one open-plan space and one or two L-shaped rooms where the rows allow."""
    pairs = _neighbours_in_row(drafts)
    # open plan: two or three neighbours with partial walls between them
    n_simple = sum(1 for d in drafts if d.simple and d.type == "room")
    runs = []
    for i, j in pairs if n_simple >= 5 else []:
        w = drafts[i].width + drafts[j].width
        if 7.0 <= w <= ROOM_MAX:
            runs.append((i, j))
    removed: set[int] = set()
    if runs and rng.random() < 0.85:
        i, j = runs[rng.integers(len(runs))]
        a, b = drafts[i], drafts[j]
        row = rows[a.row]
        x = a.cells[0][2]
        depth = row.y1 - row.y0
        frac = rng.uniform(0.35, 0.65)
        if row.hall_side > 0:  # hallway above: the partial wall grows from the far side (y0)
            seg = ((x, row.y0), (x, round(row.y0 + frac * depth, 3)))
        else:
            seg = ((x, row.y1), (x, round(row.y1 - frac * depth, 3)))
        a.type, a.cells, a.partials, a.simple = "openspace", a.cells + b.cells, [seg], False
        removed.add(j)
    # L shapes: room A takes the far part of neighbour B; B keeps the part by the hallway
    pairs = [(i, j) for i, j in _neighbours_in_row(drafts) if i not in removed and j not in removed]
    rng.shuffle(pairs)
    made, used = 0, set()
    for i, j in pairs if n_simple >= 3 else []:
        if made >= (1 if len(pairs) < 8 else 2):
            break
        if i in used or j in used:
            continue
        a, b = drafts[i], drafts[j]
        row = rows[a.row]
        depth = row.y1 - row.y0
        if depth < 5.4 or b.width > 8.0 or a.width + b.width > ROOM_MAX:
            continue
        if rng.random() < 0.5:  # the L may extend either way
            a, b = b, a
        near = round(rng.uniform(ROOM_MIN, depth - 2.6), 3)
        bx0, _, bx1, _ = b.cells[0]
        if row.hall_side > 0:
            cut = round(row.y1 - near, 3)
            far, close = (bx0, row.y0, bx1, cut), (bx0, cut, bx1, row.y1)
        else:
            cut = round(row.y0 + near, 3)
            far, close = (bx0, cut, bx1, row.y1), (bx0, row.y0, bx1, cut)
        a.cells, a.simple = a.cells + [far], False
        a.type = "room_l"
        b.cells, b.simple = [close], False
        b.type = "room_small"
        used.update((i, j))
        made += 1
    for j in sorted(removed, reverse=True):
        drafts.pop(j)


def _adjust_count(rng: np.random.Generator, drafts: list[Draft], target: int) -> None:
    """Split the widest or merge the narrowest simple rooms until there are ``target`` spaces (if possible)."""
    for _ in range(10_000):
        n = len(drafts)
        if n == target:
            return
        if n < target:
            cands = [(d.width, i) for i, d in enumerate(drafts) if d.simple and d.type == "room"
                     and d.width >= 2 * ROOM_MIN + 0.2]
            if not cands:
                return
            _, i = max(cands)
            x0, y0, x1, y1 = drafts[i].cells[0]
            lo, hi = max(0.4, ROOM_MIN / (x1 - x0)), min(0.6, 1 - ROOM_MIN / (x1 - x0))
            xm = round(x0 + (x1 - x0) * rng.uniform(lo, max(lo, hi)), 3)
            drafts[i].cells = [(x0, y0, xm, y1)]
            drafts.insert(i + 1, Draft("room", [(xm, y0, x1, y1)], row=drafts[i].row))
        else:
            pairs = [(drafts[i].width + drafts[j].width, i, j) for i, j in _neighbours_in_row(drafts)]
            pairs = [p for p in pairs if p[0] <= ROOM_MAX]
            if not pairs:
                return
            _, i, j = min(pairs)
            x0, y0, _, y1 = drafts[i].cells[0]
            x1 = drafts[j].cells[0][2]
            drafts[i].cells = [(x0, y0, x1, y1)]
            drafts.pop(j)
