"""Door and window elements of one space: frames, casings, leaves, glass and sills.

A door gives each space it joins its own ``door`` instance: the half of the
frame (jambs, head, casing) on that space's side, plus the leaf when the leaf
is in that space (an open leaf turned into the room) or closes the opening (a
closed leaf shows one face to each side).  A window belongs to the space
inside: reveals, frame, the glass (sampled sparsely, as glass returns few
points) and the sill board.
"""
from __future__ import annotations

import math

import numpy as np

from engine.synth import colours
from engine.synth.building import Element, Opening, Space, Wall
from engine.synth.faces import GLASS_DENSITY
from engine.synth.geometry import Box, Rect, at, rect, v3

UP, DOWN = np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0])
CASING_W, CASING_D = 0.07, 0.015
LEAF_T = 0.04
FRAME_W, FRAME_D = 0.05, 0.07
GLASS_INSET = 0.06  # glass plane distance from the outer face
#: The key of a door's type stream in a ``doors`` building.
DOOR_KEY = 3_000_000
#: A ``doors`` building's door types (:func:`door_type`).
DOOR_TYPES = ("classic", "flush", "glazed", "sliding")


def door_type(stream: int, opening: int) -> str:
    """The type of a door of a ``doors`` building, the same for both its sides: ``classic`` (casings, a leaf
    like the wall's doors), ``flush`` (no casing, the frame in the wall's colour), ``glazed`` (a glass leaf, few
    points) or ``sliding`` (the leaf slid along the wall's face, on one side), from the door's own stream."""
    r = np.random.default_rng([stream, int(opening), DOOR_KEY])
    return DOOR_TYPES[int(r.integers(len(DOOR_TYPES)))]


def door_side(w: Wall, o: Opening, side: int, space: Space, style: dict) -> tuple[Element, Rect]:
    """The door instance of one side of a door opening, and the floor strip under the opening on that side."""
    d, n, p0 = w.direction, w.normal, w.p0
    t, zf, zh = w.thickness, w.z0, o.z1
    face = side * t / 2
    d3, n3 = v3(d), v3(n)
    kind = door_type(style["doors"], o.id) if "doors" in style else ""
    frame_rgb = space.colours["wall"] if kind == "flush" else space.colours["door_frame"]
    leaf_rgb = space.colours["door"]
    leaf_kw = {}
    if w.material == "glass" or kind == "glazed":  # glass doors (and those of glazed partitions): sparse
        leaf_rgb, leaf_kw = colours.GLASS, {"jitter": 22.0, "density": GLASS_DENSITY}
    prims: list = [
        rect(at(p0, d, n, o.s0, 0, zf), n3 * face, [0, 0, zh - zf], d3, frame_rgb),
        rect(at(p0, d, n, o.s1, 0, zf), n3 * face, [0, 0, zh - zf], -d3, frame_rgb),
        rect(at(p0, d, n, o.s0, 0, zh), d3 * o.width, n3 * face, DOWN, frame_rgb),
    ]
    off = side * (t / 2 + CASING_D / 2)
    if kind != "flush":
        for s, size in ((o.s0 - CASING_W / 2, (CASING_W, CASING_D, zh - zf + CASING_W)),
                        (o.s1 + CASING_W / 2, (CASING_W, CASING_D, zh - zf + CASING_W))):
            c = at(p0, d, n, s, off, zf + size[2] / 2)
            prims.append(Box(c, np.array(size), w.yaw, frame_rgb))
        c = at(p0, d, n, (o.s0 + o.s1) / 2, off, zh + CASING_W / 2)
        prims.append(Box(c, np.array([o.width + 2 * CASING_W, CASING_D, CASING_W]), w.yaw, frame_rgb))
    if kind == "sliding":
        if o.leaf != "none" and o.swing == side:  # one leaf on the room's face, slid 0-95 % open
            shift = (0.95 if o.leaf == "open" else 0.0) * o.width * (1 if o.id % 2 == 0 else -1)
            c2 = at(p0, d, n, (o.s0 + o.s1) / 2 + shift, side * (t / 2 + CASING_D + 0.01 + LEAF_T / 2),
                    zf + (zh - zf) / 2)
            prims.append(Box(c2, np.array([o.width + 0.04, LEAF_T, zh - zf + 0.02]), w.yaw, leaf_rgb, **leaf_kw))
    elif o.leaf != "none":
        lw = o.width / o.leaves - 0.01
        lh = zh - zf - 0.01
        hinges = [0] if o.leaves == 1 and o.id % 2 == 0 else [1] if o.leaves == 1 else [0, 1]
        for hinge in hinges:
            s_h = o.s0 + 0.005 if hinge == 0 else o.s1 - 0.005
            closed_dir = d if hinge == 0 else -d
            if o.leaf == "closed":
                off_leaf = o.swing * max(t / 2 - 0.01 - LEAF_T / 2, 0.0)
                c2 = np.asarray(p0) + d * s_h + closed_dir * lw / 2 + n * off_leaf
                prims.append(Box(v3(c2, zf + lh / 2), np.array([lw, LEAF_T, lh]), w.yaw, leaf_rgb, **leaf_kw))
            elif o.swing == side:
                th = o.angle
                ldir = math.cos(th) * closed_dir + math.sin(th) * o.swing * n
                hinge_pt = np.asarray(p0) + d * s_h + n * o.swing * (t / 2 + 0.01)
                c2 = hinge_pt + ldir * lw / 2
                prims.append(Box(v3(c2, zf + lh / 2), np.array([lw, LEAF_T, lh]),
                                 math.atan2(ldir[1], ldir[0]), leaf_rgb, **leaf_kw))
    threshold = rect(at(p0, d, n, o.s0, 0, zf), d3 * o.width, n3 * face, UP, space.colours["floor"],
                     jitter=space.colours.get("floor_jitter", 8.0))
    info = {"opening": o.id, "type": kind} if kind else {"opening": o.id}
    return Element(-1, "door", space.id, prims, yaw=w.yaw, info=info), threshold


def window(w: Wall, o: Opening, side: int, space: Space, style: dict) -> Element:
    """Reveals, frame, sparse glass and sill board of a window seen from inside."""
    d, n, p0 = w.direction, w.normal, w.p0
    t = w.thickness
    face = side * t / 2
    glass = -side * (t / 2 - GLASS_INSET)
    d3, n3 = v3(d), v3(n)
    reveal = space.colours["wall"]
    frame = style["window_frame"]
    zs, zh = o.z0, o.z1
    depth = n3 * (face - glass)
    prims: list = [
        rect(at(p0, d, n, o.s0, glass, zs), depth, [0, 0, zh - zs], d3, reveal, jitter=5.0),
        rect(at(p0, d, n, o.s1, glass, zs), depth, [0, 0, zh - zs], -d3, reveal, jitter=5.0),
        rect(at(p0, d, n, o.s0, glass, zs), d3 * o.width, depth, UP, reveal, jitter=5.0),
        rect(at(p0, d, n, o.s0, glass, zh), d3 * o.width, depth, DOWN, reveal, jitter=5.0),
        rect(at(p0, d, n, o.s0 + FRAME_W, glass, zs + FRAME_W), d3 * (o.width - 2 * FRAME_W),
             [0, 0, zh - zs - 2 * FRAME_W], n3 * side, colours.GLASS, jitter=22.0, density=0.15),
    ]
    space.mirrors.append(prims[-1])  # the pane: reflections are seen in it (hardness artefacts)
    fo = glass + side * FRAME_D / 2
    h = zh - zs
    bars = [(o.s0 + FRAME_W / 2, (zs + zh) / 2, FRAME_W, h), (o.s1 - FRAME_W / 2, (zs + zh) / 2, FRAME_W, h),
            ((o.s0 + o.s1) / 2, zs + FRAME_W / 2, o.width, FRAME_W), ((o.s0 + o.s1) / 2, zh - FRAME_W / 2, o.width, FRAME_W)]
    if o.mullion > 0:  # bars every o.mullion metres, the panes equal
        k = max(1, round(o.width / o.mullion))
        bars += [(o.s0 + o.width * i / k, (zs + zh) / 2, FRAME_W, h - 2 * FRAME_W) for i in range(1, k)]
    elif o.width > 1.4:
        bars.append(((o.s0 + o.s1) / 2, (zs + zh) / 2, FRAME_W, h - 2 * FRAME_W))
    for s, z, bw, bh in bars:
        prims.append(Box(at(p0, d, n, s, fo, z), np.array([bw, FRAME_D, bh]), w.yaw, frame, jitter=5.0))
    if o.sill_board:
        prims.append(Box(at(p0, d, n, (o.s0 + o.s1) / 2, side * (t / 2 + 0.02), zs - 0.015),
                         np.array([o.width + 0.1, 0.04, 0.03]), w.yaw, frame, jitter=5.0))
    info = {"opening": o.id, "type": o.style} if o.style else {"opening": o.id}
    return Element(-1, "window", space.id, prims, yaw=w.yaw, info=info)
