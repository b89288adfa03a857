"""Scanning one part of a space: sample its surfaces, keep what a scanner sees, add noise and colour.

Per part (:class:`engine.synth.building.PartSpec`), all numpy over whole arrays:

1. *Sampling*: every rectangle and floor/ceiling triangle gets a Poisson number
   of uniform points (``density`` x the space's factor x the surface's own
   factor, per m^2); points in door and window holes are dropped.
2. *Visibility*: a point is kept if the segment from at least one scan position
   of its space reaches it without passing through any solid box of the space
   (furniture parts, columns, beams, door leaves; the walls too in L-shaped
   rooms).  Segments are tested against boxes with a vectorised slab test on
   (point, box) pairs; pairs are culled first per 0.5 m voxel (a box can only
   hide a voxel's points if it is near the segment from the scanner to the
   voxel).  So there is no floor under a bookcase, no wall behind it, no back
   face of anything, and the floor under a table shows only between its legs.
3. *Noise* along the surface normal (sigma per space, clipped at `noise_clip` sigmas: 3, or 5 in a varied
   room; no point goes deeper than that into a wall), *colour* from the surface's
   base colour with jitter, the space's brightness and a distance fall-off.
4. The building's frame maps the points to world coordinates.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry import Polygon

from engine.synth.building import Building, Frame, PartSpec, Space
from engine.synth.colours import shade
from engine.synth.geometry import Box, Poly, Rect
from engine.synth.streams import S_SCAN, rng_for

VOXEL = 0.5
PAIR_CHUNK = 2_000_000
EPS = 0.002  # a segment must pass this far (m) inside a box, short of its end, to count as blocked


@dataclass
class ScanJob:
    """Everything one task needs to scan one part: small to pickle (one space, not the building)."""

    part: PartSpec
    space: Space
    frame: Frame
    seed: int
    density: float


def part_jobs(building: Building) -> list[ScanJob]:
    """One job per part of the building, in part order."""
    return [ScanJob(p, building.spaces[p.space], building.frame, building.seed, building.density)
            for p in building.parts]


def scan_part(building: Building, part: PartSpec | int) -> dict[str, np.ndarray]:
    """The points of one part: world ``x, y, z`` (float64), ``red, green, blue`` (uint16, 0-255), ground truth."""
    if not isinstance(part, PartSpec):
        part = building.parts[int(part)]
    return scan_job(ScanJob(part, building.spaces[part.space], building.frame, building.seed, building.density))


def scan_building(building: Building) -> dict[str, np.ndarray]:
    """All parts of a (small) building concatenated in part order."""
    cols = [scan_part(building, p) for p in building.parts]
    return {k: np.concatenate([c[k] for c in cols]) for k in cols[0]}


COLUMNS = {"x": np.float64, "y": np.float64, "z": np.float64, "red": np.uint16, "green": np.uint16,
           "blue": np.uint16, "gt_space": np.int32, "gt_class": np.uint8, "gt_instance": np.int32}


def scan_job(job: ScanJob) -> dict[str, np.ndarray]:
    """Scan one part (see the module docstring; hard scan conditions: :mod:`engine.synth.hard.scan`)."""
    sp, part = job.space, job.part
    if not sp.scanned:
        return {k: np.empty(0, t) for k, t in COLUMNS.items()}
    rng = rng_for(job.seed, S_SCAN, sp.id, part.piece)
    rects, tris = _surfaces(sp, part)
    rate = job.density * sp.density
    pts, nrm, surf = [], [], []
    base, jit, elem = [], [], []
    if rects:
        p, n, i = _sample_rects(rng, [r for r, _, _ in rects], rate)
        pts.append(p), nrm.append(n), surf.append(i)
        base.append(np.array([r.rgb for r, _, _ in rects], float))
        jit.append(np.array([r.jitter for r, _, _ in rects]))
        elem.append(np.array([e for _, e, _ in rects], np.int64))
    if tris:
        tri = np.concatenate([t[0] for t in tris])
        up = np.concatenate([np.full(len(t[0]), t[1].up) for t in tris])
        dens = np.concatenate([np.full(len(t[0]), t[1].density) for t in tris])
        p, n, i = _sample_tris(rng, tri, up, dens * rate)
        pts.append(p), nrm.append(n), surf.append(i + sum(len(b) for b in base))
        base.append(np.concatenate([np.tile(t[1].rgb, (len(t[0]), 1)) for t in tris]).astype(float))
        jit.append(np.concatenate([np.full(len(t[0]), t[1].jitter) for t in tris]))
        elem.append(np.concatenate([np.full(len(t[0]), t[2], np.int64) for t in tris]))
    if not pts:
        return {k: np.empty(0, t) for k, t in COLUMNS.items()}
    P, S = np.concatenate(pts), np.concatenate(surf)
    normals = np.concatenate(nrm)  # one per surface
    base, jit, elem = np.concatenate(base), np.concatenate(jit), np.concatenate(elem)
    boxes = [b for e in sp.elements for b in e.prims if isinstance(b, Box)] + list(sp.occluders)
    # nearest scanners first: the later ones only test what the earlier ones could not see
    axis_xy = sp.footprint[:, part.axis]
    centre = (max(part.lo, axis_xy.min()) + min(part.hi, axis_xy.max())) / 2
    order = np.argsort(np.abs(sp.scanners[:, part.axis] - centre), kind="stable")
    scanners = sp.scanners[order]
    first = seen_by(P, scanners, boxes)
    keep = first >= 0
    P, S, first = P[keep], S[keep], first[keep]
    n = len(P)
    sigma = sp.noise
    bound = sp.noise_bound
    P += normals[S] * np.clip(rng.standard_normal(n, dtype=np.float32) * sigma, -bound, bound)[:, None]
    dist = np.sqrt(np.sum((P - scanners[0]) ** 2, axis=1))  # light falls off from the part's nearest scanner
    rgb = shade(rng, base[S], jit[S], sp.brightness, dist)
    el = elem[S]
    ids = np.array([e.id for e in sp.elements], np.int32)
    codes = np.array([e.class_code for e in sp.elements], np.uint8)
    space = np.full(n, sp.id, np.int32)
    cls, inst = codes[el], ids[el]
    if sp.flying > 0 or sp.ghosts > 0 or sp.registration is not None:
        P, rgb, space, cls, inst, first = _hard(job, P, S, first, rects, scanners, order, rgb, space, cls, inst)
    world = job.frame.xyz(P)
    if sp.voxel > 0:
        keep = nearest_in_cell(world, sp.voxel)
        world, rgb, space, cls, inst = world[keep], rgb[keep], space[keep], cls[keep], inst[keep]
    return {"x": world[:, 0], "y": world[:, 1], "z": world[:, 2],
            "red": rgb[:, 0], "green": rgb[:, 1], "blue": rgb[:, 2],
            "gt_space": space, "gt_class": cls, "gt_instance": inst}


def _hard(job: ScanJob, P, S, first, rects, scanners, order, rgb, space, cls, inst):
    """Flying points, reflections and registration errors (:mod:`engine.synth.hard.scan`)."""
    from engine.synth.hard import scan as hard_scan
    from engine.synth.hard.hardness import hard_rng

    sp = job.space
    if sp.flying > 0:
        frng = hard_rng(job.seed, "artefacts", 0, sp.id, job.part.piece)
        faces = np.array([f for _, _, f in rects], bool)
        moved = hard_scan.flying_points(frng, sp, P, S, [r for r, _, _ in rects], faces, scanners[first])
        k = next(i for i, e in enumerate(sp.elements) if e.info.get("kind") == "flying")
        cls[moved], inst[moved] = sp.elements[k].class_code, sp.elements[k].id
    if sp.ghosts > 0:
        grng = hard_rng(job.seed, "artefacts", 1, sp.id, job.part.piece)
        src, G = hard_scan.reflections(grng, sp, P, scanners[0])
        if len(src):
            P = np.concatenate([P, G])
            rgb = np.concatenate([rgb, (rgb[src] * 0.55).astype(rgb.dtype)])
            space = np.concatenate([space, np.full(len(src), -1, np.int32)])
            cls = np.concatenate([cls, np.full(len(src), hard_scan.CLUTTER, np.uint8)])
            inst = np.concatenate([inst, np.full(len(src), -1, np.int32)])
            first = np.concatenate([first, first[src]])
    if sp.registration is not None:
        jitter = sp.scan_jitter[order] if sp.scan_jitter is not None else None
        P = hard_scan.register(sp, P, first, scanners, jitter)
    return P, rgb, space, cls, inst, first


# -- surfaces of a part ---------------------------------------------------------------------
def _surfaces(sp: Space, part: PartSpec) -> tuple[list[tuple[Rect, int, bool]], list[tuple[np.ndarray, Poly, int]]]:
    """Rectangles ``(rect, element index, is a box face)`` and triangle sets ``(tris (k, 3, 3), poly, element
    index)`` of the part."""
    rects, tris = [], []
    whole = part.pieces == 1
    for ei, e in enumerate(sp.elements):
        for prim in e.prims:
            if isinstance(prim, Rect):
                r = prim if whole else _clip_rect(prim, part)
                if r is not None:
                    rects.append((r, ei, False))
            elif isinstance(prim, Poly):
                t = _triangles(prim, None if whole else part)
                if len(t):
                    tris.append((t, prim, ei))
            elif whole or part.lo <= prim.center[part.axis] < part.hi:
                rects += [(f, ei, True) for f in prim.faces(sp.z0, sp.z1)]
    return rects, tris


def nearest_in_cell(xyz: np.ndarray, size: float) -> np.ndarray:
    """The indices, in order, of the point nearest the centre of each occupied cell of the grid ``size`` wide (a
    voxel subsampling like PDAL's ``filters.voxelcenternearestneighbor``; a cell cut by a part's border keeps a
    point on each side)."""
    if len(xyz) == 0:
        return np.zeros(0, np.int64)
    scaled = np.asarray(xyz, float) / size
    cells = np.floor(scaled).astype(np.int64)
    cells -= cells.min(axis=0)
    span = cells.max(axis=0) + 1
    key = (cells[:, 0] * span[1] + cells[:, 1]) * span[2] + cells[:, 2]
    off = np.sum((scaled - cells - np.floor(scaled.min(axis=0)) - 0.5) ** 2, axis=1)
    order = np.lexsort((np.arange(len(key)), off, key))
    first = np.ones(len(order), bool)
    first[1:] = key[order[1:]] != key[order[:-1]]
    return np.sort(order[first])


def _clip_rect(r: Rect, part: PartSpec) -> Rect | None:
    """The piece of a rectangle inside the part's slab (whole if it lies across the slab axis)."""
    a = part.axis
    ua, va = float(r.u[a]), float(r.v[a])
    if abs(va) < 1e-12 < abs(ua):
        lo, hi = sorted(((part.lo - r.origin[a]) / ua, (part.hi - r.origin[a]) / ua))
        lo, hi = max(lo, 0.0), min(hi, 1.0)
        if hi <= lo:
            return None
        if lo == 0.0 and hi == 1.0:
            return r
        ul = float(np.linalg.norm(r.u))
        holes = [(s0 - lo * ul, s1 - lo * ul, t0, t1) for s0, s1, t0, t1 in r.holes]
        return Rect(r.origin + lo * r.u, (hi - lo) * r.u, r.v, r.rgb, holes, r.jitter, r.density)
    if abs(ua) < 1e-12 < abs(va):
        lo, hi = sorted(((part.lo - r.origin[a]) / va, (part.hi - r.origin[a]) / va))
        lo, hi = max(lo, 0.0), min(hi, 1.0)
        if hi <= lo:
            return None
        if lo == 0.0 and hi == 1.0:
            return r
        vl = float(np.linalg.norm(r.v))
        holes = [(s0, s1, t0 - lo * vl, t1 - lo * vl) for s0, s1, t0, t1 in r.holes]
        return Rect(r.origin + lo * r.v, r.u, (hi - lo) * r.v, r.rgb, holes, r.jitter, r.density)
    c = r.origin[a] + (ua + va) / 2
    return r if part.lo <= c < part.hi else None


def _triangles(poly: Poly, part: PartSpec | None) -> np.ndarray:
    """Triangles ``(k, 3, 3)`` covering the polygon (clipped to the part's slab)."""
    g = Polygon(poly.xy)
    if part is not None:
        lo = [-1e9, -1e9]
        hi = [1e9, 1e9]
        lo[part.axis] = max(part.lo, -1e9)
        hi[part.axis] = min(part.hi, 1e9)
        g = shapely.clip_by_rect(g, lo[0], lo[1], hi[0], hi[1])
        if g.is_empty:
            return np.empty((0, 3, 3))
    t = shapely.constrained_delaunay_triangles(g)
    xy = shapely.get_coordinates(shapely.get_parts(t)).reshape(-1, 4, 2)[:, :3]
    return np.concatenate([xy, np.full(xy.shape[:2] + (1,), poly.z)], axis=2)


# -- sampling -----------------------------------------------------------------------------------
def _sample_rects(rng: np.random.Generator, rects: list[Rect], rate: float):
    O = np.array([r.origin for r in rects], float)
    U = np.array([r.u for r in rects], float)
    V = np.array([r.v for r in rects], float)
    cross = np.cross(U, V)
    area = np.linalg.norm(cross, axis=1)
    normal = cross / np.maximum(area, 1e-12)[:, None]
    counts = rng.poisson(area * rate * np.array([r.density for r in rects]))
    idx = np.repeat(np.arange(len(rects)), counts)
    st = rng.random((len(idx), 2))
    P = O[idx] + st[:, :1] * U[idx] + st[:, 1:] * V[idx]
    keep = np.ones(len(idx), bool)
    starts = np.r_[0, np.cumsum(counts)]
    ul, vl = np.linalg.norm(U, axis=1), np.linalg.norm(V, axis=1)
    for k, r in enumerate(rects):
        if not r.holes or counts[k] == 0:
            continue
        a, b = starts[k], starts[k + 1]
        s, t = st[a:b, 0] * ul[k], st[a:b, 1] * vl[k]
        for s0, s1, t0, t1 in r.holes:
            keep[a:b] &= ~((s > s0) & (s < s1) & (t > t0) & (t < t1))
    return P[keep], normal, idx[keep]


def _sample_tris(rng: np.random.Generator, tri: np.ndarray, up: np.ndarray, rate: np.ndarray):
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    area = np.linalg.norm(np.cross(e1, e2), axis=1) / 2
    counts = rng.poisson(area * rate)
    idx = np.repeat(np.arange(len(tri)), counts)
    r1 = np.sqrt(rng.random(len(idx)))[:, None]
    r2 = rng.random(len(idx))[:, None]
    P = (1 - r1) * tri[idx, 0] + r1 * (1 - r2) * tri[idx, 1] + r1 * r2 * tri[idx, 2]
    normal = np.zeros((len(tri), 3))
    normal[:, 2] = np.where(up, 1.0, -1.0)
    return P, normal, idx


# -- visibility ---------------------------------------------------------------------------------
def box_arrays(boxes: list[Box]) -> dict[str, np.ndarray]:
    """Centres, half sizes, yaw cosines/sines and axis-aligned bounds of boxes."""
    c = np.array([b.center for b in boxes], float).reshape(-1, 3)
    h = np.array([b.size for b in boxes], float).reshape(-1, 3) / 2
    yaw = np.array([b.yaw for b in boxes], float)
    cs, sn = np.cos(yaw), np.sin(yaw)
    ex = np.abs(cs) * h[:, 0] + np.abs(sn) * h[:, 1]
    ey = np.abs(sn) * h[:, 0] + np.abs(cs) * h[:, 1]
    half = np.c_[ex, ey, h[:, 2]]
    return {"c": c, "h": h, "cos": cs, "sin": sn, "lo": c - half, "hi": c + half}


def visible(points: np.ndarray, scanners: np.ndarray, boxes: list[Box]) -> np.ndarray:
    """True for points seen from at least one scanner: the segment to it crosses no box.

    Works in float32 (local coordinates, far below the 2 mm tolerance) on points
    sorted by voxel, so each box's candidate points are a few contiguous runs.
    """
    return seen_by(points, scanners, boxes) >= 0


def seen_by(points: np.ndarray, scanners: np.ndarray, boxes: list[Box]) -> np.ndarray:
    """Index of the first scanner (in the given order) that sees each point, -1 if none does."""
    n = len(points)
    first = np.full(n, -1, np.int64)
    if n == 0:
        return first
    if not boxes:
        first[:] = 0
        return first
    B = box_arrays(boxes)
    todo = np.arange(n)
    for k, s in enumerate(np.asarray(scanners, float)):
        if not len(todo):
            break
        blocked = _blocked(points[todo], s, B)
        first[todo[~blocked]] = k
        todo = todo[blocked]
    return first


def _blocked(p: np.ndarray, s: np.ndarray, B: dict[str, np.ndarray]) -> np.ndarray:
    """True for points whose segment from scanner ``s`` passes through one of the boxes ``B``."""
    n, m = len(p), len(B["c"])
    # group points in voxels; keep the boxes near the segment from the scanner to each voxel
    k = np.floor(p * (1.0 / VOXEL)).astype(np.int64)
    kmin = k.min(0)
    k -= kmin
    dims = k.max(0) + 1
    key = (k[:, 0] * dims[1] + k[:, 1]) * dims[2] + k[:, 2]
    del k
    order = np.argsort(key, kind="stable")  # points sorted by voxel
    skey = key[order]
    pstart = np.flatnonzero(np.r_[True, skey[1:] != skey[:-1]])
    pcount = np.diff(np.r_[pstart, n])
    uniq = skey[pstart]
    del key, skey
    vk = np.c_[uniq // (dims[1] * dims[2]), (uniq // dims[2]) % dims[1], uniq % dims[2]]
    vc = (vk + kmin + 0.5) * VOXEL
    r = VOXEL * math.sqrt(3) / 2
    cand_v, cand_b = [], []
    step = max(1, 1_000_000 // max(m, 1))
    for a in range(0, len(vc), step):
        vi, bi = np.nonzero(_segments_hit_aabbs(s, vc[a:a + step], B["lo"] - r, B["hi"] + r))
        cand_v.append(vi + a)
        cand_b.append(bi)
    cand_v, cand_b = np.concatenate(cand_v), np.concatenate(cand_b)
    blocked = np.zeros(n, bool)
    if not len(cand_v):
        return blocked
    # relative to the scanner, in float32, sorted by voxel
    q = (p[order] - s).astype(np.float32)
    hit = np.zeros(n, bool)
    # candidate voxels sorted by box: one vectorised test per box over the points of its voxels
    o = np.argsort(cand_b, kind="stable")
    cand_v, cand_b = cand_v[o], cand_b[o]
    bounds = np.flatnonzero(np.r_[True, cand_b[1:] != cand_b[:-1], True])
    for a, b in zip(bounds[:-1], bounds[1:]):
        j = cand_b[a]
        vs = cand_v[a:b]
        lens = pcount[vs]
        total = int(lens.sum())
        idx = np.repeat(pstart[vs] - (np.cumsum(lens) - lens), lens) + np.arange(total)
        idx = idx[~hit[idx]]
        if len(idx):
            hit[idx[_segment_box(q[idx], s, B, j)]] = True
    blocked[order] = hit
    return blocked


def _segments_hit_aabbs(s: np.ndarray, q: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``(len(q), len(lo))``: does the segment ``s -> q[i]`` meet the box ``[lo[j], hi[j]]``?"""
    d = q - s
    d = np.where(np.abs(d) < 1e-12, 1e-12, d)
    tmin = np.zeros((len(q), len(lo)))
    tmax = np.ones((len(q), len(lo)))
    for a in range(3):
        inv = 1.0 / d[:, a:a + 1]
        t1 = (lo[None, :, a] - s[a]) * inv
        t2 = (hi[None, :, a] - s[a]) * inv
        np.maximum(tmin, np.minimum(t1, t2), out=tmin)
        np.minimum(tmax, np.maximum(t1, t2), out=tmax)
    return tmin <= tmax


def _segment_box(q: np.ndarray, s: np.ndarray, B: dict[str, np.ndarray], j: int) -> np.ndarray:
    """Slab test of the segments from scanner ``s`` to ``s + q[i]`` against oriented box ``j``.

    True where the box hides the end point: the segment enters the box more than
    ``EPS`` before its end (points on the box's own visible faces stay visible).
    """
    cs, sn = np.float32(B["cos"][j]), np.float32(B["sin"][j])
    d0 = s - B["c"][j]
    sl = np.array([B["cos"][j] * d0[0] + B["sin"][j] * d0[1], -B["sin"][j] * d0[0] + B["cos"][j] * d0[1], d0[2]])
    h = B["h"][j]
    dx, dy, dz = q[:, 0], q[:, 1], q[:, 2]
    dirs = (cs * dx + sn * dy, -sn * dx + cs * dy, dz)
    tnear = np.full(len(q), -np.inf, np.float32)
    tfar = np.full(len(q), np.inf, np.float32)
    with np.errstate(divide="ignore", invalid="ignore"):
        for a in range(3):
            inv = np.float32(1.0) / dirs[a]
            t1 = np.float32(-h[a] - sl[a]) * inv
            t2 = np.float32(h[a] - sl[a]) * inv
            np.maximum(tnear, np.fmin(t1, t2), out=tnear)
            np.minimum(tfar, np.fmax(t1, t2), out=tfar)
    eps = np.float32(EPS) / np.maximum(np.sqrt(dx * dx + dy * dy + dz * dz), np.float32(1e-6))
    return (tnear <= tfar) & (tnear < 1.0 - eps) & (tfar > eps)
