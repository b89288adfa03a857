"""Wall faces of one space: one ``wall`` instance per edge of its clear footprint, with holes at openings.

Walls are annotated as S3DIS does, per room: one ``wall`` instance per edge of
the space's clear footprint (a maximal straight run of wall face, possibly
across several physical walls; the edges of a curved wall: one instance), with
holes where doors and windows are.  The inside of a wall is never sampled: only
its faces, each from its own space.  Glazed partitions (``Wall.material ==
"glass"``) are sparse glass between mullions and rails; a partial wall (inside
an open-plan space) is a solid box.
"""
from __future__ import annotations

import math

import numpy as np

from engine.synth import colours
from engine.synth.building import Element, Opening, Space, Wall
from engine.synth.geometry import Box, rect, v3

GLASS_DENSITY = 0.06  # glazed partitions and glass doors return few points


def footprint_edges(space: Space) -> list[tuple[np.ndarray, np.ndarray]]:
    fp = space.footprint
    return [(fp[i], fp[(i + 1) % len(fp)]) for i in range(len(fp))]


def face_on_edge(space: Space, w: Wall, a: np.ndarray, e: np.ndarray) -> np.ndarray | None:
    """Start of ``w``'s face seen from ``space`` when that face lies on the footprint edge through ``a`` along ``e``."""
    d, n = w.direction, w.normal
    if abs(d[0] * e[1] - d[1] * e[0]) > 1e-6:
        return None
    face0 = np.asarray(w.p0) + n * w.side_of(space.id) * w.thickness / 2
    return None if abs(float(np.dot(a - face0, n))) > 1e-5 else face0


def edge_openings(space: Space, walls: list[Wall], a: np.ndarray, b: np.ndarray) -> list[tuple[float, float, Opening]]:
    """Openings on the footprint edge ``a -> b``: ``(s0, s1, opening)`` in metres from ``a``."""
    e = b - a
    length = float(np.hypot(*e))
    e = e / length
    out = []
    for wid in space.walls:
        w = walls[wid]
        if w.kind == "partial" or not w.openings:
            continue
        face0 = face_on_edge(space, w, a, e)
        if face0 is None:
            continue
        d = w.direction
        for o in w.openings:
            q0 = float(np.dot(face0 + d * o.s0 - a, e))
            q1 = float(np.dot(face0 + d * o.s1 - a, e))
            s0, s1 = max(min(q0, q1), 0.0), min(max(q0, q1), length)
            if s1 - s0 > 1e-6:
                out.append((s0, s1, o))
    return out


def add_wall_faces(space: Space, walls: list[Wall]) -> None:
    """Append the space's wall faces (one ``wall`` element per footprint edge or curved run) to its elements."""
    cols = space.colours
    z0, z1 = space.z0, space.z1
    faces = []
    for a, b in footprint_edges(space):
        e = b - a
        length = float(np.hypot(*e))
        inward = np.array([-e[1], e[0]]) / length
        holes = [(s0, s1, o.z0 - z0, min(o.z1, z1) - z0) for s0, s1, o in edge_openings(space, walls, a, b)]
        glass = glazed_parts(space, walls, a, b, holes)
        holes += [g["hole"] for g in glass]
        r = rect(v3(a, z0), v3(e), [0, 0, z1 - z0], v3(inward), cols["wall"], holes=holes, jitter=5.0)
        faces.append(([r] + [p for g in glass for p in g["prims"]], math.atan2(e[1], e[0]), length))
    for group in curve_groups(faces):
        prims = [p for i in group for p in faces[i][0]]
        yaw = faces[max(group, key=lambda i: faces[i][2])][1]
        space.elements.append(Element(-1, "wall", space.id, prims, yaw=yaw))


def curve_groups(faces: list[tuple[list, float, float]], max_turn: float = 35.0) -> list[list[int]]:
    """Consecutive footprint edges turning by less than ``max_turn`` degrees (a curved wall): one group each."""
    n = len(faces)
    if n == 0:
        return []
    turn = [abs(math.remainder(faces[(i + 1) % n][1] - faces[i][1], 2 * math.pi)) for i in range(n)]
    smooth = [math.degrees(t) < max_turn for t in turn]  # edge i continues into edge i + 1
    groups: list[list[int]] = [[0]]
    for i in range(1, n):
        if smooth[i - 1]:
            groups[-1].append(i)
        else:
            groups.append([i])
    if len(groups) > 1 and smooth[n - 1]:
        groups[0] = groups.pop() + groups[0]
    return groups


def glazed_parts(space: Space, walls: list[Wall], a: np.ndarray, b: np.ndarray,
                 holes: list[tuple[float, float, float, float]]) -> list[dict]:
    """The glazed partitions along a footprint edge: their hole in the opaque face and their prims.

    A glass wall's face is sparse glass (6 % of the density) between the
    glazing heights, with its door openings left out; mullions every 1.0-1.5 m
    (the same for both faces: from the wall's own start), a bottom rail and a
    head rail at normal density, each half as deep as the wall (the half on
    this side).  Below and above the glazing the face stays solid.
    """
    e = b - a
    length = float(np.hypot(*e))
    if length < 1e-9:
        return []
    e = e / length
    inward = np.array([-e[1], e[0]])
    z0, z1 = space.z0, space.z1
    out = []
    for wid in space.walls:
        w = walls[wid]
        if w.material != "glass" or w.kind == "partial":
            continue
        face0 = face_on_edge(space, w, a, e)
        if face0 is None:
            continue
        d = w.direction
        q0, q1 = float(np.dot(face0 - a, e)), float(np.dot(face0 + d * w.length - a, e))
        s0, s1 = max(min(q0, q1), 0.0), min(max(q0, q1), length)
        if s1 - s0 < 0.05:
            continue
        g0, g1 = w.glazing
        g1 = min(g1, z1 - z0 - 0.02)
        if g1 - g0 < 0.3:
            continue
        glass_holes = [(max(h0, s0) - s0, min(h1, s1) - s0, t0 - g0, t1 - g0) for h0, h1, t0, t1 in holes
                       if h1 > s0 and h0 < s1]
        prims: list = [rect(v3(a + e * s0, z0 + g0), v3(e * (s1 - s0)), [0, 0, g1 - g0], v3(inward),
                            colours.GLASS, holes=glass_holes, jitter=22.0, density=GLASS_DENSITY)]
        depth = w.thickness / 2
        frame = space.colours.get("door_frame", (180, 180, 180))
        yaw = math.atan2(e[1], e[0])
        pitch = 1.0 + 0.5 * ((wid * 0.6180339887) % 1.0)
        along = np.arange(pitch, w.length - 0.05, pitch)
        for t in along:  # positions along the wall -> along this edge
            s = float(np.dot(face0 + d * t - a, e))
            if not s0 + 0.03 < s < s1 - 0.03 or any(h0 - 0.03 < s < h1 + 0.03 for h0, h1, _, _ in holes):
                continue
            c = a + e * s - inward * depth / 2
            prims.append(Box(v3(c, z0 + (g0 + g1) / 2), np.array([0.05, depth, g1 - g0]), yaw, frame, jitter=5.0))
        mid = a + e * (s0 + s1) / 2 - inward * depth / 2
        for zc in (g0 + 0.025, g1 - 0.025):
            prims.append(Box(v3(mid, z0 + zc), np.array([s1 - s0, depth, 0.05]), yaw, frame, jitter=5.0))
        out.append({"hole": (s0, s1, g0, g1), "prims": prims})
    return out


def partial_wall(w: Wall, cols: dict) -> Element:
    """A wall inside an open-plan space: a solid box from the wall it leans on to its free end."""
    d, _n = w.direction, w.normal
    s0, s1 = w.ext0, w.length - w.ext1
    mid = np.asarray(w.p0) + d * (s0 + s1) / 2
    b = Box(np.array([mid[0], mid[1], (w.z0 + w.z1) / 2]), np.array([s1 - s0, w.thickness, w.z1 - w.z0]),
            w.yaw, cols["wall"], jitter=5.0)
    return Element(-1, "wall", w.left, [b], yaw=w.yaw, info={"partial": True})

