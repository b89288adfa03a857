"""The placer: the free space of one room, where furniture pieces are set down.

A :class:`Placer` holds a space's clear footprint, its wall edges with their
openings, and the 3-D boxes already taken (structural elements, door
clearances, tall strips in front of windows, pieces placed so far).  A piece
(a list of :data:`engine.synth.pieces.Part` in its own frame) is turned by a
yaw, set down at a point, and kept only if it stays inside the footprint and
off every occupied box.  Used by the room recipes
(:mod:`engine.synth.furniture`) and the difficulties' pieces
(:mod:`engine.synth.hard.furniture`).
"""
from __future__ import annotations

import math

import numpy as np
import shapely
from shapely.geometry import Polygon

from engine.synth.building import Element, Space, Wall
from engine.synth.faces import edge_openings, footprint_edges
from engine.synth.geometry import Box
from engine.synth.pieces import Part


class Placer:
    """Free space of one room: clear footprint, wall edges with their openings, occupied 3-D boxes."""

    def __init__(self, rng: np.random.Generator, space: Space, walls: list[Wall], style: dict):
        self.rng, self.space, self.style = rng, space, style
        self.hard = None
        self.poly = Polygon(space.footprint)
        shapely.prepare(self.poly)
        lo, hi = space.footprint.min(0), space.footprint.max(0)
        self.rectangular = abs((hi - lo).prod() - self.poly.area) < 1e-6
        self.occupied = np.empty((0, 6))
        self.edges = []
        z0 = space.z0
        for a, b in footprint_edges(space):
            e = b - a
            length = float(np.hypot(*e))
            self.edges.append({"a": a, "e": e / length, "n": np.array([-e[1], e[0]]) / length, "len": length,
                               "openings": [(s0, s1, o) for s0, s1, o in edge_openings(space, walls, a, b)]})
        # keep doorways clear on this side (and the swing of leaves turning into this room)
        for ed in self.edges:
            for s0, s1, o in ed["openings"]:
                if o.kind == "door":
                    reach = 1.1 if o.leaf != "open" else (s1 - s0) / o.leaves + 0.3
                    self._block_strip(ed, s0 - 0.25, s1 + 0.25, max(reach, 1.0), z0, space.z1)
                else:  # only tall things (bookcases, not chairs) are kept off windows
                    self._block_strip(ed, s0 - 0.05, s1 + 0.05, 0.45, o.z0 + 0.2, o.z1)
        for e in space.elements:  # columns, beams, partial walls, lights, door leaves and casings
            for b in e.prims:
                if isinstance(b, Box):
                    self.occupy(b.corners())

    def _block_strip(self, ed, s0, s1, depth, z0, z1):
        a, e, n = ed["a"], ed["e"], ed["n"]
        pts = np.array([a + e * s0, a + e * s1, a + e * s0 + n * depth, a + e * s1 + n * depth])
        self.occupied = np.vstack([self.occupied, np.r_[pts.min(0), z0, pts.max(0), z1]])

    def occupy(self, corners: np.ndarray) -> None:
        self.occupied = np.vstack([self.occupied, np.r_[corners.min(0), corners.max(0)]])

    def fits(self, parts: list[Box], margin: float = 0.02) -> bool:
        corners = np.concatenate([b.corners() for b in parts])
        lo, hi = corners.min(0) + margin, corners.max(0) - margin
        o = self.occupied
        if len(o) and np.any((lo[0] < o[:, 3]) & (hi[0] > o[:, 0]) & (lo[1] < o[:, 4]) & (hi[1] > o[:, 1])
                             & (lo[2] < o[:, 5]) & (hi[2] > o[:, 2])):
            return False
        xy = corners[:, :2]
        if self.rectangular:
            flo, fhi = self.space.footprint.min(0), self.space.footprint.max(0)
            return bool(np.all(xy >= flo - 1e-9) and np.all(xy <= fhi + 1e-9))
        hull = shapely.convex_hull(shapely.multipoints(xy))
        return bool(self.poly.contains(hull))

    def build(self, parts: list[Part], xy, yaw: float, z: float = None) -> list[Box]:
        z = self.space.z0 if z is None else z
        c, s = math.cos(yaw), math.sin(yaw)
        out = []
        for cx, cy, cz, sx, sy, sz, rgb, *turn in parts:  # an eighth value turns the part about z
            wx = xy[0] + c * cx - s * cy
            wy = xy[1] + s * cx + c * cy
            out.append(Box(np.array([wx, wy, z + cz]), np.array([sx, sy, sz], float), yaw + sum(turn), tuple(rgb)))
        return out

    def put(self, cls: str, parts: list[Part], xy, yaw: float, z: float = None, *, margin: float = 0.02,
            info: dict | None = None) -> Element | None:
        boxes = self.build(parts, xy, yaw, z)
        if not self.fits(boxes, margin):
            return None
        for b in boxes:
            self.occupy(b.corners())
        el = Element(-1, cls, self.space.id, boxes, yaw=yaw, info=info or {})
        self.space.elements.append(el)
        return el

    # wall positions
    def wall_spot(self, width: float, depth: float, height: float, gap: float = 0.02, bottom: float = 0.0,
                  edge: int | None = None):
        """A random spot against a wall: centre xy and yaw facing into the room (local +y to the wall)."""
        choices = [i for i, ed in enumerate(self.edges) if ed["len"] >= width + 0.1] if edge is None else [edge]
        if not choices:
            return None
        lens = np.array([self.edges[i]["len"] for i in choices])
        i = choices[int(self.rng.choice(len(choices), p=lens / lens.sum()))]
        ed = self.edges[i]
        s = self.rng.uniform(0.05, ed["len"] - width - 0.05) if ed["len"] - width > 0.1 else (ed["len"] - width) / 2
        for s0, s1, o in ed["openings"]:
            if s < s1 + 0.05 and s + width > s0 - 0.05 and (o.kind == "door" or bottom < o.z1 - self.space.z0
                                                          and bottom + height > o.z0 - self.space.z0):
                return None
        n = ed["n"]
        xy = ed["a"] + ed["e"] * (s + width / 2) + n * (gap + depth / 2)
        return xy, math.atan2(n[0], -n[1]), i

    def against_wall(self, cls: str, make, width: float, depth: float, height: float, *, tries: int = 12,
                     bottom: float = 0.0, gap: float = 0.02, edge: int | None = None, info=None) -> Element | None:
        for _ in range(tries):
            spot = self.wall_spot(width, depth, height, gap, bottom, edge)
            if spot is None:
                continue
            el = self.put(cls, make(), spot[0], spot[1], info=info)
            if el is not None:
                return el
        return None

    def free_spot(self, tries: int, place) -> Element | None:
        lo, hi = self.space.footprint.min(0), self.space.footprint.max(0)
        for _ in range(tries):
            xy = self.rng.uniform(lo, hi)
            el = place(xy)
            if el is not None:
                return el
        return None
