"""Tiny hand-made buildings for the space-parsing tests: box-shell rooms separated by wall voids.

Each room is an axis-aligned clear rectangle; its points are its floor, its
ceiling and the inner faces of its four walls (what a scanner inside sees), so
two rooms ``wall`` metres apart leave an empty wall void between their faces.
Doors cut an opening in both faces and put the jambs and the threshold inside
the void.  The whole building can be turned by a yaw and moved, and is written
as a tile store with ``gt_space`` per point.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from tiles.builder import StoreBuilder
from tiles.groundtruth import gt_dimensions
from tiles.schema import Part, Source, coordinate_dimensions
from tiles.store import TileStore


@dataclass
class Room:
    x0: float
    y0: float
    x1: float
    y1: float
    floor: int = 0


@dataclass
class Plan:
    rooms: list[Room]
    #: (room a, room b, position along the shared wall from its lower end, width)
    doors: list[tuple[int, int, float, float]] = field(default_factory=list)
    height: float = 2.8
    storey: float = 3.3  # floor-to-floor height
    wall: float = 0.2


def _rect(rng, n, a0, a1, b0, b1):
    return rng.uniform(a0, a1, n), rng.uniform(b0, b1, n)


def sample(plan: Plan, *, density: float = 300.0, seed: int = 0, clutter: bool = True,
           noise: float = 0.003) -> tuple[np.ndarray, np.ndarray]:
    """Points ``(n, 3)`` and their ground-truth room index, ``density`` points per m² of surface."""
    rng = np.random.default_rng(seed)
    pts, lab = [], []
    h = plan.height

    def add(xyz, room):
        pts.append(xyz)
        lab.append(np.full(len(xyz), room, dtype=np.int32))

    openings = _openings(plan)
    for k, r in enumerate(plan.rooms):
        z0 = r.floor * plan.storey
        w, d = r.x1 - r.x0, r.y1 - r.y0
        for z in (z0, z0 + h):  # floor and ceiling
            n = rng.poisson(density * w * d)
            x, y = _rect(rng, n, r.x0, r.x1, r.y0, r.y1)
            add(np.stack([x, y, np.full(n, z)], 1), k)
        faces = [("x", r.x0, r.y0, r.y1), ("x", r.x1, r.y0, r.y1), ("y", r.y0, r.x0, r.x1), ("y", r.y1, r.x0, r.x1)]
        for axis, at, a0, a1 in faces:
            n = rng.poisson(density * (a1 - a0) * h)
            a, z = _rect(rng, n, a0, a1, z0, z0 + h)
            keep = np.ones(n, bool)
            for (ax2, at2, b0, b1, top, fl) in openings:
                if ax2 == axis and abs(at2 - at) <= plan.wall / 2 + 1e-6 and r.floor == fl:
                    keep &= ~((a >= b0) & (a <= b1) & (z <= z0 + top))
            a, z = a[keep], z[keep]
            xy = np.stack([np.full(len(a), at), a], 1) if axis == "x" else np.stack([a, np.full(len(a), at)], 1)
            add(np.column_stack([xy, z]), k)
        if clutter:  # a few boxes against the walls and in the middle: tables, bookcases
            for _ in range(max(1, int(w * d / 8))):
                bw, bd, bh = rng.uniform(0.4, 1.6), rng.uniform(0.3, 0.9), rng.uniform(0.5, 2.0)
                cx, cy = rng.uniform(r.x0 + bw / 2, max(r.x0 + bw / 2, r.x1 - bw / 2)), rng.uniform(
                    r.y0 + bd / 2, max(r.y0 + bd / 2, r.y1 - bd / 2))
                add(_box(rng, cx, cy, z0, bw, bd, bh, density), k)
    # doors: jambs and threshold inside the wall void, labelled as the first room
    for (a, _b, _pos, width), (axis, at, b0, b1, top, _) in zip(plan.doors, openings):
        ra = plan.rooms[a]
        z0 = ra.floor * plan.storey
        n = rng.poisson(density * width * plan.wall)
        s, t = _rect(rng, n, b0, b1, at - plan.wall / 2, at + plan.wall / 2)
        xy = np.stack([t, s], 1) if axis == "x" else np.stack([s, t], 1)
        add(np.column_stack([xy, np.full(n, z0)]), a)
        for jamb in (b0, b1):
            n = rng.poisson(density * plan.wall * top)
            t, z = _rect(rng, n, at - plan.wall / 2, at + plan.wall / 2, z0, z0 + top)
            xy = np.stack([t, np.full(n, jamb)], 1) if axis == "x" else np.stack([np.full(n, jamb), t], 1)
            add(np.column_stack([xy, z]), a)
    xyz = np.concatenate(pts)
    xyz += rng.normal(0, noise, xyz.shape)
    return xyz, np.concatenate(lab)


def _openings(plan: Plan) -> list[tuple[str, float, float, float, float]]:
    """Per door: (axis of the wall normal, wall centre, opening start, end, height, floor)."""
    out = []
    for a, b, pos, width in plan.doors:
        ra, rb = plan.rooms[a], plan.rooms[b]
        if abs(rb.x0 - ra.x1) <= plan.wall + 1e-6 or abs(ra.x0 - rb.x1) <= plan.wall + 1e-6:
            at = (ra.x1 + rb.x0) / 2 if rb.x0 >= ra.x1 - 1e-6 else (rb.x1 + ra.x0) / 2
            lo = max(ra.y0, rb.y0)
            out.append(("x", at, lo + pos, lo + pos + width, 2.1, ra.floor))
        else:
            at = (ra.y1 + rb.y0) / 2 if rb.y0 >= ra.y1 - 1e-6 else (rb.y1 + ra.y0) / 2
            lo = max(ra.x0, rb.x0)
            out.append(("y", at, lo + pos, lo + pos + width, 2.1, ra.floor))
    return out


def _box(rng, cx, cy, z0, w, d, h, density):
    area = 2 * (w * d) + 2 * (w * h) + 2 * (d * h)
    n = rng.poisson(density * area)
    u = rng.uniform(-0.5, 0.5, (n, 3)) * [w, d, h]
    face = rng.integers(0, 3, n)
    sign = np.where(rng.random(n) < 0.5, -0.5, 0.5)
    dims = np.array([w, d, h])
    u[np.arange(n), face] = sign * dims[face]
    keep = ~((face == 2) & (sign < 0))  # no bottom face
    return (u + [cx, cy, z0 + h / 2])[keep]


def transform(xyz: np.ndarray, yaw_deg: float = 0.0, offset=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Turn points about z by ``yaw_deg`` and move them by ``offset``."""
    a = math.radians(yaw_deg)
    c, s = math.cos(a), math.sin(a)
    out = xyz.copy()
    out[:, 0] = c * xyz[:, 0] - s * xyz[:, 1]
    out[:, 1] = s * xyz[:, 0] + c * xyz[:, 1]
    return out + np.asarray(offset)


def write_store(path, xyz: np.ndarray, gt: np.ndarray | None = None, *, client=None, tile_size: float = 10.0,
                scale: float = 0.001) -> TileStore:
    """A tile store of the points (and ``gt_space``), built with :class:`tiles.builder.StoreBuilder`."""
    offset = np.floor(xyz.min(axis=0))
    raw = np.round((xyz - offset) / scale).astype(np.int32)
    cols = {"x": raw[:, 0], "y": raw[:, 1], "z": raw[:, 2]}
    dims = coordinate_dimensions()
    if gt is not None:
        dims = dims + [gt_dimensions()[0]]
        cols["gt_space"] = gt.astype(np.int32)
    b = StoreBuilder.create(str(path), dimensions=dims, scale=[scale] * 3, offset=[float(v) for v in offset],
                            tile_size=tile_size, overwrite=True)
    s = b.write_part(0, cols)
    return b.finalize([s], parts=[Part(0, 0, len(raw))], sources=[Source("handmade", "test", len(raw))],
                      client=client)


def corridor_plan(n_rooms: int = 4, room_w: float = 4.0, room_d: float = 5.0, corridor: float = 2.0,
                  wall: float = 0.2, floors: int = 1) -> Plan:
    """Rooms on both sides of a corridor, one door from each room to the corridor."""
    rooms: list[Room] = []
    doors = []
    for f in range(floors):
        base = len(rooms)
        length = n_rooms * room_w + (n_rooms - 1) * wall
        rooms.append(Room(0.0, room_d + wall, length, room_d + wall + corridor, f))  # corridor
        for side in (0, 1):
            for i in range(n_rooms):
                x0 = i * (room_w + wall)
                y0 = 0.0 if side == 0 else room_d + 2 * wall + corridor
                rooms.append(Room(x0, y0, x0 + room_w, y0 + room_d, f))
                doors.append((len(rooms) - 1, base, 1.0, 0.9))
    return Plan(rooms, doors, wall=wall)


# --- loose point sets for the refinement's raster tests (ridges, ceilings) ---------------------------------------

def box_points(rng: np.random.Generator, n: int, u, v, z) -> np.ndarray:
    """``n`` points uniform in the box ``u x v x z`` (pairs of bounds)."""
    return np.stack([rng.uniform(*u, n), rng.uniform(*v, n), rng.uniform(*z, n)], axis=1)


#: Raster bin across and in height, and the first bin of the upper band (2.2 m over a floor at z 0).
BW, ZB = 0.01, 0.02
BAND = int(round(2.2 / ZB))


def point_bins(pts: np.ndarray, bw: float = BW, zb: float = ZB) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Histogram bins (u, v, z) of points: ``bw`` across, ``zb`` in height."""
    return (np.floor(pts[:, 0] / bw).astype(np.int64), np.floor(pts[:, 1] / bw).astype(np.int64),
            np.floor(pts[:, 2] / zb).astype(np.int64))


def generated_stores(root, seeds_yaws, rooms: int = 2, density: float = 600) -> list:
    """Small generated buildings (engine.synth) under ``root``, one per ``(seed, yaw)``, opened as tile stores."""
    from engine.synth import generate
    from tiles.store import open_store

    stores = []
    for seed, yaw in seeds_yaws:
        generate(str(root / f"b{seed}.zarr"), seed=seed, rooms=rooms, density=density, yaw=yaw)
        stores.append(open_store(str(root / f"b{seed}.zarr")))
    return stores
