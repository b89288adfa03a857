"""Floors of general polygons: walls where spaces meet, at any angle, and spaces planned in their own frame.

The clean generator's floors are rectangles cut into axis-aligned cells, and
:func:`engine.synth.walls.grid_walls` finds walls on the cells' grid lines exactly.
Non-rectangular floors (a wing at an angle, chamfered and rounded corners,
slanted or curved walls, a stair tower) describe each space by its centre-line
polygon instead, and :func:`walls_from_polygons` finds the walls the same way
for any polygon: every edge of every space's ring (counter-clockwise, so the
space is on its left) is split at every vertex of any space lying on it, each
piece asks which space is just beyond it (right side), and runs with the same
two spaces become one wall.  Every interior wall is seen from both rings and
kept from the ring of the lower id; exterior walls (nothing beyond) from their
one ring.  Walls on one line share a thickness.

Spaces of a wing have their own frame (``Space.axis``, radians): their
structure, furniture and scan positions are planned in it by
:func:`in_local_frame`, which turns the space (and the walls it needs) by
``-axis`` about the floor's origin, runs the planner, and turns every new
primitive back, so axis-aligned planners (column grids, beams, lights,
conference tables, desk grids) line up with a wing's walls.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any

import numpy as np
import shapely
from shapely.geometry import Polygon
from shapely.geometry.polygon import orient

from engine.synth.building import Element, Space, Wall
from engine.synth.geometry import Box, Poly, Rect

#: Points closer than this (m) to an edge's line lie on it.
ON_LINE = 1e-5
#: How far beyond an edge the space on its right is sought (m).
PROBE = 2e-3


def rotation(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def rotate_xy(xy: np.ndarray, angle: float) -> np.ndarray:
    """Points ``(..., 2)`` turned by ``angle`` about the origin (unchanged when the angle is 0)."""
    if angle == 0.0:
        return np.asarray(xy, float)
    return np.asarray(xy, float) @ rotation(angle).T


def _ring(poly: Polygon) -> np.ndarray:
    return np.asarray(orient(poly, 1.0).exterior.coords)[:-1]


def walls_from_polygons(polys: dict[int, Polygon], partials: dict[int, list], floor: int, z: float,
                        spaces: list[Space], thickness: Callable[[tuple], float], ext_t: float,
                        first_id: int) -> list[Wall]:
    """The walls of a floor of space polygons (centre lines); ``thickness(line key)`` draws an interior thickness.

    ``partials`` are the partial walls ``((x, y), (x, y))`` inside each space
    (open-plan spaces), kept as walls of kind ``partial``.
    """
    ids = sorted(polys)
    rings = {sid: _ring(shapely.simplify(polys[sid], 0)) for sid in ids}
    verts = np.concatenate([rings[s] for s in ids])
    pieces: list[tuple[int, int, np.ndarray, np.ndarray]] = []  # (left, right, a, b)
    probes, owners = [], []
    for sid in ids:
        ring = rings[sid]
        for k in range(len(ring)):
            a, b = ring[k], ring[(k + 1) % len(ring)]
            e = b - a
            length = float(np.hypot(*e))
            if length < 1e-9:
                continue
            d = e / length
            n = np.array([-d[1], d[0]])
            rel = verts - a
            t = rel @ d
            off = rel @ n
            cuts = np.unique(np.r_[0.0, t[(np.abs(off) < ON_LINE) & (t > ON_LINE) & (t < length - ON_LINE)], length])
            for t0, t1 in zip(cuts[:-1], cuts[1:]):
                if t1 - t0 < ON_LINE:
                    continue
                pieces.append((sid, -1, a + d * t0, a + d * t1))
                probes.append(a + d * (t0 + t1) / 2 - n * PROBE)
                owners.append(len(pieces) - 1)
    probes = np.asarray(probes).reshape(-1, 2)
    right = np.full(len(pieces), -1, dtype=np.int64)
    for sid in ids:
        inside = shapely.contains_xy(polys[sid], probes[:, 0], probes[:, 1])
        right[np.asarray(owners)[inside]] = sid
    # runs of pieces along one ring with the same right side and direction join into one wall
    runs: list[list] = []
    for (left, _, a, b), r in zip(pieces, right):
        r = int(r)
        if r == left:
            continue
        if r >= 0 and r < left:
            continue  # seen from the lower id's ring
        if runs:
            pl, pr, pa, pb = runs[-1]
            if pl == left and pr == r and np.allclose(pb, a, atol=1e-9) and _collinear(pa, pb, b):
                runs[-1][3] = b
                continue
        runs.append([left, r, a, b])
    # a ring's first and last runs may be one straight wall cut by the ring's start
    merged: list[list] = []
    for run in runs:
        merged.append(run)
    runs = _join_wraparound(merged)
    walls: list[Wall] = []
    raw = []
    for left, r, a, b in runs:
        key = line_key(a, b)
        if r < 0:
            t, kind = ext_t, "exterior"
        else:
            t, kind = thickness(key), "interior"
        raw.append((tuple(a), tuple(b), left, r, t, kind))
    for sid in sorted(partials):
        for p, q in partials[sid]:
            raw.append((tuple(p), tuple(q), sid, sid, None, "partial"))
    for k, (p0, p1, left, r, t, kind) in enumerate(raw):
        if t is None:
            t = thickness(("partial", k))
        zs = [spaces[s].z1 for s in (left, r) if s >= 0]
        walls.append(Wall(first_id + k, floor, (float(p0[0]), float(p0[1])), (float(p1[0]), float(p1[1])),
                          float(t), z, max(zs), left, r, kind))
    joint_reach(walls)
    return walls


def _collinear(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> bool:
    d1, d2 = b - a, c - b
    n1, n2 = np.hypot(*d1), np.hypot(*d2)
    if n1 < 1e-12 or n2 < 1e-12:
        return True
    return abs(d1[0] * d2[1] - d1[1] * d2[0]) / (n1 * n2) < 1e-7 and float(np.dot(d1, d2)) > 0


def _join_wraparound(runs: list[list]) -> list[list]:
    """Join the last run of a ring into its first when they continue one another on the same line."""
    out: list[list] = []
    start = 0
    for i in range(len(runs) + 1):
        if i == len(runs) or (i > start and runs[i][0] != runs[start][0]):
            ring_runs = runs[start:i]
            if len(ring_runs) > 1:
                first, last = ring_runs[0], ring_runs[-1]
                if last[1] == first[1] and np.allclose(last[3], first[2], atol=1e-9) \
                        and _collinear(last[2], last[3], first[3]):
                    first[2] = last[2]
                    ring_runs = ring_runs[:-1]
            out += ring_runs
            start = i
    return out


def line_key(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """The line a wall lies on: its direction modulo 180 degrees and its distance from the origin."""
    d = np.asarray(b, float) - np.asarray(a, float)
    ang = math.atan2(d[1], d[0]) % math.pi
    if ang > math.pi - 1e-6:
        ang = 0.0
    n = np.array([-math.sin(ang), math.cos(ang)])
    return round(ang, 4), round(float(np.dot(n, a)), 3)


def joint_reach(walls: list[Wall]) -> None:
    """How far each wall body reaches past its ends into the walls it meets, at any angle.

    A wall ending on another's centre line at angle ``a`` reaches ``h / sin(a)``
    into it (``h`` the other's half thickness; capped at three times ``h``);
    nearly collinear neighbours (the segments of an arc) meet with a mitre.
    """
    if not walls:
        return
    p0 = np.array([w.p0 for w in walls], float)
    d = np.array([w.direction for w in walls])
    n = np.c_[-d[:, 1], d[:, 0]]
    length = np.array([w.length for w in walls])
    half = np.array([w.thickness for w in walls]) / 2
    for k, w in enumerate(walls):
        sin = np.abs(d[:, 0] * d[k, 1] - d[:, 1] * d[k, 0])
        for end in (0, 1):
            rel = np.asarray(w.p0 if end == 0 else w.p1) - p0
            along = np.einsum("ij,ij->i", rel, d)
            off = np.einsum("ij,ij->i", rel, n)
            meets = (np.abs(off) < 1e-6) & (along >= -1e-6) & (along <= length + 1e-6)
            meets[k] = False
            steep = meets & (sin >= math.sin(math.radians(25)))
            shallow = meets & (sin > 1e-9) & ~steep
            reach = 0.0
            if steep.any():
                reach = float(np.max(np.minimum(half[steep] / sin[steep], 3 * half[steep])))
            if shallow.any():
                a = np.arcsin(np.clip(sin[shallow], 0, 1))
                reach = max(reach, float(np.max(half[k] * np.tan(a / 2) + half[shallow] * np.tan(a / 2))) + 1e-3)
            if w.kind == "partial" and reach == 0.0:
                continue
            if end == 0:
                w.ext0 = reach
            else:
                w.ext1 = reach


def clear_footprints(polys: dict[int, Polygon], walls: list[Wall], spaces: list[Space]) -> None:
    """Clear floor polygon of each space: its polygon minus every wall body (partial walls stay inside)."""
    bodies = shapely.union_all([Polygon(w.body()) for w in walls if w.kind != "partial"])
    for sid, poly in polys.items():
        clear = shapely.set_precision(poly.difference(bodies), 1e-6)
        if clear.geom_type != "Polygon":
            clear = max(getattr(clear, "geoms", [clear]), key=lambda g: g.area)
        clear = orient(shapely.simplify(clear, 0), 1.0)
        spaces[sid].footprint = np.asarray(clear.exterior.coords)[:-1]


# -- planning a space in its own frame ---------------------------------------------------------
def rotate_prim(p: Any, angle: float) -> Any:
    """A primitive turned by ``angle`` about the vertical through the floor's origin."""
    if isinstance(p, Rect):
        r3 = np.eye(3)
        r3[:2, :2] = rotation(angle)
        return dataclasses.replace(p, origin=r3 @ np.asarray(p.origin, float), u=r3 @ np.asarray(p.u, float),
                                   v=r3 @ np.asarray(p.v, float))
    if isinstance(p, Poly):
        return dataclasses.replace(p, xy=rotate_xy(p.xy, angle))
    if isinstance(p, Box):
        c = np.asarray(p.center, float).copy()
        c[:2] = rotate_xy(c[:2], angle)
        return dataclasses.replace(p, center=c, yaw=p.yaw + angle)
    raise TypeError(type(p))


def rotate_element(e: Element, angle: float) -> None:
    e.prims = [rotate_prim(p, angle) for p in e.prims]
    e.yaw += angle
    if e.center is not None:
        c = np.asarray(e.center, float).copy()
        c[:2] = rotate_xy(c[:2], angle)
        e.center = c


def rotate_wall(w: Wall, angle: float) -> Wall:
    p0, p1 = rotate_xy(np.array([w.p0, w.p1]), angle)
    return dataclasses.replace(w, p0=(float(p0[0]), float(p0[1])), p1=(float(p1[0]), float(p1[1])))


def _turn_space(space: Space, angle: float) -> None:
    space.footprint = rotate_xy(space.footprint, angle)
    for e in space.elements:
        rotate_element(e, angle)
    space.occluders = [rotate_prim(b, angle) for b in space.occluders]
    space.mirrors = [rotate_prim(r, angle) for r in space.mirrors]
    if space.scanners is not None and len(space.scanners):
        sc = np.asarray(space.scanners, float).copy()
        sc[:, :2] = rotate_xy(sc[:, :2], angle)
        space.scanners = sc


def in_local_frame(space: Space, walls: list[Wall], fn: Callable[[list[Wall]], Any]) -> Any:
    """Run ``fn(walls)`` with the space (and its walls) turned into its own frame, then turn everything back.

    ``space.cells`` are kept in the space's own frame at all times; a space
    with ``axis == 0`` runs ``fn`` as it is.
    """
    if space.axis == 0.0:
        return fn(walls)
    local = list(walls)
    for wid in space.walls:
        local[wid] = rotate_wall(walls[wid], -space.axis)
    _turn_space(space, -space.axis)
    try:
        return fn(local)
    finally:
        _turn_space(space, space.axis)
