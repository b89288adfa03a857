"""Doors and windows of a floor: where they go on its walls.

Doors are chosen so that every space of the floor is reachable from its
hallways: circulation joins circulation through wide doors held open, every
room opens on the circulation it touches, whatever is still cut off joins
through any neighbour, and a few extra doors link neighbouring rooms; the
ground floor's lobby gets an exterior double door.  Windows are regularly
spaced on exterior walls (fewer in WCs and storage rooms).  Their elements
(frames, leaves, glass) are drawn per space by :mod:`engine.synth.frames`.
"""
from __future__ import annotations

import math
from collections import defaultdict

import numpy as np

from engine.synth.building import Opening, Space, Wall
from engine.synth.layout import CIRCULATION, Draft


def door_room(w: Wall, width: float) -> tuple[float, float] | None:
    """The range of door centres along a wall that keeps a door of ``width`` clear of the joints."""
    lo = max(w.ext0, 0.05) + 0.18 + width / 2
    hi = w.length - max(w.ext1, 0.05) - 0.18 - width / 2
    return (lo, hi) if hi >= lo else None


class _DoorPlanner:
    """The doors of one floor so far: the walls each pair of spaces shares and which spaces they join."""

    def __init__(self, rng: np.random.Generator, walls: list[Wall], spaces: list[Space], openings: list[Opening],
                 drafts: dict[int, Draft], closed: set[int]):
        self.rng, self.spaces, self.openings, self.drafts, self.closed = rng, spaces, openings, drafts, closed
        self.by_pair: dict[tuple[int, int], list[Wall]] = defaultdict(list)
        for w in walls:
            if w.kind == "interior":
                self.by_pair[tuple(sorted((w.left, w.right)))].append(w)
        self.circ = {sid for sid in drafts if spaces[sid].type in CIRCULATION}
        self.parent = {sid: sid for sid in drafts}
        self.pairs = sorted(self.by_pair)

    def find(self, a: int) -> int:
        parent = self.parent
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    def best_wall(self, pair: tuple[int, int], width: float) -> Wall | None:
        ws = [w for w in self.by_pair.get(pair, []) if door_room(w, width)]
        return max(ws, key=lambda w: w.length) if ws else None

    def add(self, pair: tuple[int, int], double: bool = False, leaf: str | None = None) -> bool:
        """A door between the two spaces of ``pair`` on their longest shared wall; False if none has room."""
        rng, spaces, circ, closed = self.rng, self.spaces, self.circ, self.closed
        a, b = pair
        width = rng.uniform(1.5, 1.9) if double else rng.uniform(0.8, 1.0)
        w = self.best_wall(pair, width)
        if w is None and double:
            double, width = False, rng.uniform(0.8, 1.0)
            w = self.best_wall(pair, width)
        if w is None:
            return False
        lo, hi = door_room(w, width)
        c = rng.uniform(lo, hi)
        zmax = min(spaces[s].z1 for s in pair) - w.z0 - 0.25
        h = min(rng.uniform(2.0, 2.2), zmax)
        if leaf is None:
            r = rng.random()
            leaf = "closed" if r < 0.45 else "open" if r < 0.9 else "none"
        if closed and (a in closed or b in closed):
            leaf = "closed"
        # leaves swing into the room, not the hallway
        into = b if a in circ and b not in circ else a if b in circ and a not in circ else pair[rng.integers(2)]
        swing = w.side_of(into)
        o = Opening(len(self.openings), "door", w.id, round(c - width / 2, 4), round(c + width / 2, 4), w.z0,
                    round(w.z0 + h, 4), leaf=leaf, leaves=2 if double else 1, swing=swing,
                    angle=float(rng.uniform(math.radians(60), math.radians(100))))
        w.openings.append(o)
        self.openings.append(o)
        self.parent[self.find(a)] = self.find(b)
        return True

    def join_circulation(self) -> None:
        """Hallways and lobby join each other through wide doors held open."""
        for a, b in self.pairs:
            if a in self.circ and b in self.circ:
                self.add((a, b), double=True, leaf=str(self.rng.choice(["open", "none"])))

    def open_rooms(self) -> None:
        """Every room opens on the circulation it touches (the longest such wall)."""
        circ = self.circ
        for sid in sorted(self.drafts):
            if sid in circ:
                continue
            cands = [p for p in self.pairs if sid in p and (p[0] in circ or p[1] in circ)]
            if cands:
                p = max(cands, key=lambda p: max(w.length for w in self.by_pair[p]))
                big = self.spaces[sid].type in ("conferenceRoom", "openspace") and self.rng.random() < 0.5
                self.add(p, double=big)

    def connect_rest(self) -> None:
        """Whatever is still cut off joins through any neighbour."""
        drafts, find = self.drafts, self.find
        for _ in range(len(drafts)):
            roots = {find(s) for s in drafts}
            if len(roots) == 1:
                break
            main = find(min(self.circ)) if self.circ else find(min(drafts))
            linked = False
            for p in self.pairs:
                if (find(p[0]) == main) != (find(p[1]) == main):
                    if self.add(p):
                        linked = True
                        break
            if not linked:
                break

    def add_extra(self) -> None:
        """A few extra doors between neighbouring rooms."""
        circ, find = self.circ, self.find
        for p in self.pairs:
            if p[0] not in circ and p[1] not in circ and find(p[0]) == find(p[1]) and self.rng.random() < 0.12:
                if not any(o for w in self.by_pair[p] for o in w.openings):
                    self.add(p)

    def add_exterior(self, walls: list[Wall]) -> None:
        """The entrance: a closed double door on the lobby's longest exterior wall."""
        rng, spaces = self.rng, self.spaces
        lobby = [sid for sid in self.drafts if spaces[sid].type == "lobby"] or sorted(self.circ)[:1]
        ext = [w for w in walls if w.kind == "exterior" and lobby and lobby[0] in (w.left, w.right)]
        ext = [w for w in ext if door_room(w, 1.8)]
        if ext:
            w = max(ext, key=lambda w: w.length)
            lo, hi = door_room(w, 1.8)
            c = rng.uniform(lo, hi)
            h = min(2.3, spaces[lobby[0]].z1 - w.z0 - 0.3)
            o = Opening(len(self.openings), "door", w.id, round(c - 0.9, 4), round(c + 0.9, 4), w.z0,
                        round(w.z0 + h, 4), leaf="closed", leaves=2, swing=w.side_of(lobby[0]))
            w.openings.append(o)
            self.openings.append(o)


def place_doors(rng: np.random.Generator, walls: list[Wall], spaces: list[Space], openings: list[Opening],
                drafts: dict[int, Draft], exterior_door: bool, closed: set[int] = frozenset()) -> None:
    """Doors so that every space of the floor is reachable, plus a few extra between rooms.

    The doors of the spaces in ``closed`` (rooms never scanned) are closed.
    """
    doors = _DoorPlanner(rng, walls, spaces, openings, drafts, closed)
    doors.join_circulation()
    doors.open_rooms()
    doors.connect_rest()
    doors.add_extra()
    if exterior_door:
        doors.add_exterior(walls)


#: The key of an exterior wall's window-type stream in a ``windows`` building.
WINDOW_KEY = 2_000_000


def window_type(stream: int, wall: int) -> dict:
    """The window type of an exterior wall of a ``windows`` building, from the wall's own stream: punched
    windows of any size, a ribbon along the wall, full-height windows or tall narrow ones; mullions in half of
    them (a ribbon's always), a sill board inside in half of those not at the floor."""
    r = np.random.default_rng([stream, int(wall), WINDOW_KEY])
    kind = ("punched", "ribbon", "full", "tall")[int(r.integers(4))]
    if kind == "punched":
        t = dict(window_width=r.uniform(0.6, 2.4), window_gap=r.uniform(0.4, 2.5), sill=r.uniform(0.5, 1.1),
                 window_height=r.uniform(0.9, 2.0))
    elif kind == "ribbon":
        t = dict(window_width=math.inf, window_gap=0.0, sill=r.uniform(0.8, 1.1), window_height=r.uniform(0.6, 1.4))
    elif kind == "full":
        t = dict(window_width=r.uniform(0.8, 2.6), window_gap=r.uniform(0.2, 1.5), sill=r.uniform(0.0, 0.15),
                 window_height=math.inf, head_gap=r.uniform(0.05, 0.4))
    else:
        t = dict(window_width=r.uniform(0.45, 0.9), window_gap=r.uniform(0.5, 1.5), sill=r.uniform(0.3, 0.8),
                 window_height=r.uniform(1.8, 2.6))
    t["mullion"] = r.uniform(0.9, 1.8) if kind == "ribbon" else (r.uniform(0.5, 1.2) if r.random() < 0.5 else 0.0)
    t["sill_board"] = bool(t["sill"] > 0.3 and r.random() < 0.5)
    t["type"] = kind
    return t


def place_windows(rng: np.random.Generator, walls: list[Wall], spaces: list[Space], openings: list[Opening],
                  style: dict) -> None:
    """Regularly spaced windows on exterior walls (fewer in WCs and storage rooms); in a ``windows`` building,
    of each wall's type (:func:`window_type`)."""
    for w in walls:
        if w.kind != "exterior":
            continue
        sid = w.left if w.left >= 0 else w.right
        sp = spaces[sid]
        if sp.type in ("WC", "storage") and rng.random() < 0.5:
            continue
        t = window_type(style["windows"], w.id) if "windows" in style else style
        lo = w.ext0 + 0.35
        hi = w.length - w.ext1 - 0.35
        taken = [(o.s0 - 0.3, o.s1 + 0.3) for o in w.openings]
        sill = w.z0 + t["sill"]
        head = min(sill + t["window_height"], sp.z1 - t.get("head_gap", 0.3))
        if head - sill < 0.5:
            continue
        for s0, s1 in _window_spans(lo, hi, t["window_width"], t["window_gap"], taken):
            o = Opening(len(openings), "window", w.id, round(s0, 4), round(s1, 4), round(sill, 4), round(head, 4),
                        mullion=float(t.get("mullion", 0.0)), sill_board=bool(t.get("sill_board", True)),
                        style=t.get("type", ""))
            w.openings.append(o)
            openings.append(o)


def _window_spans(lo: float, hi: float, width: float, gap: float,
                  taken: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """Windows ``width`` wide, ``gap`` apart, centred on ``lo..hi``, clear of ``taken``; an infinite width is a
    ribbon: one window over each stretch of ``lo..hi`` at least 0.9 m long between the taken ones."""
    if math.isinf(width):
        spans, x = [], lo
        for a, b in sorted(taken) + [(hi, hi)]:
            if min(a, hi) - x >= 0.9:
                spans.append((x, min(a, hi)))
            x = max(x, b)
        return spans
    usable = hi - lo
    period = width + gap
    n = int((usable + gap) // period)
    if n < 1:
        if usable < 0.9:
            return []
        n, width = 1, min(width, usable)
    start = lo + (usable - (n * width + (n - 1) * gap)) / 2
    spans = [(start + k * period, start + k * period + width) for k in range(n)]
    return [(s0, s1) for s0, s1 in spans if not any(s0 < b and s1 > a for a, b in taken)]
