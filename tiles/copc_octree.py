"""The COPC octree of an export: the root cube, each point's cell, the groups of work and which node holds a point.

Every point gets integer cell coordinates ``q`` on a ``2**BITS`` grid per axis
of the cube (:func:`point_cells`); a node at level ``d`` is ``q >> (BITS - d)``.
A node whose cube cell holds more than ``cap`` points (over the whole cloud) is
*sampled*: it keeps one point per cell of a ``2**grid_bits`` grid of its own
(the arriving point nearest the cell centre, ties to the smaller point index)
and passes the rest to its children; any other node is a *leaf* and keeps every
point that arrives.  So a node's points lie in its cube, coarse levels are an
even sample and a leaf holds at most ``cap`` points.

The work is cut in *groups* (:func:`plan_groups`): the largest nodes of at most
``group_points`` points (at level ``grid_bits`` at the deepest).  A group's
points are all a worker needs for the nodes inside it, and for its share of
the *top* nodes above it, since each sampling cell of a top node lies inside
one group.  Design: docs/design/tiles.md, "COPC".
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Bits of the integer cell coordinates per axis (three of them pack into an int64).
BITS = 21
#: A sampled node keeps one point per cell of a ``2**GRID_BITS`` grid over it (128**3, as untwine and PDAL).
GRID_BITS = 7


@dataclass(frozen=True)
class Cube:
    """The root cube of the octree (world coordinates) and the sampling grid of a node."""

    center: tuple[float, float, float]
    halfsize: float
    grid_bits: int = GRID_BITS

    @property
    def mins(self) -> np.ndarray:
        return np.asarray(self.center, dtype=np.float64) - self.halfsize

    @property
    def depth(self) -> int:
        """The deepest level: its nodes' sampling cells are the finest cells."""
        return BITS - self.grid_bits

    @property
    def spacing(self) -> float:
        """The distance between the root's points (COPC info ``spacing``): its sampling cell edge."""
        return 2 * self.halfsize / (1 << self.grid_bits)

    def bounds(self, level: int, key: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
        """World (min, max) corners of node ``key`` at ``level``."""
        side = 2 * self.halfsize / (1 << level)
        lo = self.mins + np.asarray(key, dtype=np.float64) * side
        return lo, lo + side


def cube_for(bounds: list[float], scale: list[float], grid_bits: int = GRID_BITS) -> Cube:
    """The cube around world ``bounds`` ``[minx, miny, minz, maxx, maxy, maxz]``: centred, a hair larger."""
    if not 1 <= grid_bits <= 10:
        raise ValueError(f"grid_bits must be 1-10, not {grid_bits}")
    lo, hi = np.asarray(bounds[:3], dtype=np.float64), np.asarray(bounds[3:], dtype=np.float64)
    center = (lo + hi) / 2
    half = float(np.max(hi - lo)) / 2
    half = half * (1 + 2.0 ** -20) + float(max(scale))
    return Cube(tuple(float(c) for c in center), half, grid_bits)  # type: ignore[arg-type]


def point_cells(raw: dict[str, np.ndarray] | np.ndarray, scale, offset, cube: Cube) -> np.ndarray:
    """Integer cell coordinates ``(n, 3)`` int64 on the ``2**BITS`` grid of the cube, of raw scaled integers
    (``raw["X"]``... of LAS records or ``raw["x"]``... of store columns); world = raw * scale + offset."""
    names = "XYZ" if "X" in _names(raw) else "xyz"
    n = len(raw[names[0]])
    q = np.empty((n, 3), dtype=np.int64)
    top = (1 << BITS) - 1
    k = float(1 << BITS) / (2 * cube.halfsize)
    for i, a in enumerate(names):
        w = np.asarray(raw[a], dtype=np.float64) * float(scale[i]) + float(offset[i])
        t = np.floor((w - cube.mins[i]) * k)
        q[:, i] = np.clip(t, 0, top).astype(np.int64)
    return q


def _names(raw) -> tuple[str, ...]:
    return tuple(raw.dtype.names or ()) if isinstance(raw, np.ndarray) else tuple(raw)


def pack(keys: np.ndarray) -> np.ndarray:
    """Node keys ``(n, 3)`` (each < 2**BITS) as one int64 each; sorting them sorts by x, then y, then z."""
    return (keys[:, 0] << (2 * BITS)) | (keys[:, 1] << BITS) | keys[:, 2]


def unpack(packed: np.ndarray) -> np.ndarray:
    """The inverse of :func:`pack`."""
    m = (1 << BITS) - 1
    return np.stack([(packed >> (2 * BITS)) & m, (packed >> BITS) & m, packed & m], axis=1)


def _spread(v: np.ndarray) -> np.ndarray:
    """The low 21 bits of ``v`` moved to every third bit (bit ``b`` to bit ``3 b``)."""
    v = v & 0x1FFFFF
    v = (v | (v << 32)) & 0x1F00000000FFFF
    v = (v | (v << 16)) & 0x1F0000FF0000FF
    v = (v | (v << 8)) & 0x100F00F00F00F00F
    v = (v | (v << 4)) & 0x10C30C30C30C30C3
    return (v | (v << 2)) & 0x1249249249249249


def morton(keys: np.ndarray, level: int) -> np.ndarray:
    """Morton codes of node keys at ``level`` (x in the lowest bit of each triple, as COPC numbers children):
    the code of a node's parent is ``code >> 3``, so every node is a contiguous range of finer codes."""
    if not 0 <= level <= BITS:
        raise ValueError(f"level must be 0-{BITS}, not {level}")
    k = np.asarray(keys, dtype=np.int64) & ((1 << level) - 1)
    return _spread(k[:, 0]) | (_spread(k[:, 1]) << 1) | (_spread(k[:, 2]) << 2)


def demorton(code: int, level: int) -> tuple[int, int, int]:
    """The key ``(x, y, z)`` of one Morton code at ``level``."""
    out = [0, 0, 0]
    for b in range(level):
        for i in range(3):
            out[i] |= ((code >> (3 * b + i)) & 1) << b
    return out[0], out[1], out[2]


@dataclass
class Group:
    """A unit of work: the node ``(level, key)``, the range ``[lo, hi)`` of its Morton codes at ``grid_bits``
    and its point count."""

    level: int
    key: tuple[int, int, int]
    lo: int
    hi: int
    count: int


def plan_groups(codes: np.ndarray, counts: np.ndarray, cube: Cube, group_points: int) -> list[Group]:
    """The groups of the whole cloud, in Morton order, from the point count per Morton code at level
    ``grid_bits`` (``codes`` sorted, unique): the largest nodes holding at most ``group_points`` points,
    nodes at level ``grid_bits`` whatever they hold.  The nodes above them are the top nodes (:func:`top_keys`)."""
    K = cube.grid_bits
    csum = np.r_[0, np.cumsum(counts)]
    out: list[Group] = []
    stack = [(0, 0)]
    while stack:
        level, code = stack.pop()
        shift = 3 * (K - level)
        lo, hi = code << shift, (code + 1) << shift
        n = int(csum[np.searchsorted(codes, hi)] - csum[np.searchsorted(codes, lo)])
        if n == 0:
            continue
        if n <= group_points or level == K:
            out.append(Group(level, demorton(code, level), lo, hi, n))
        else:
            stack.extend((level + 1, code * 8 + c) for c in range(7, -1, -1))
    out.sort(key=lambda g: g.lo)
    return out


def ancestors(level: int, key: tuple[int, int, int]) -> list[tuple[int, tuple[int, int, int]]]:
    """The nodes above ``(level, key)``, root first."""
    return [(d, (key[0] >> (level - d), key[1] >> (level - d), key[2] >> (level - d))) for d in range(level)]


def assign_levels(q: np.ndarray, index: np.ndarray, group_level: int, cap: int, cube: Cube) -> np.ndarray:
    """The level of the node holding each point of one group (``q`` its cells, ``index`` its point indices).

    The nodes above the group (levels ``< group_level``) are sampled (they hold
    more than ``group_points >= cap`` points); a node inside it is sampled when
    its cell holds more than ``cap`` of the group's points (all of the cloud's
    in that cell) and it is above the deepest level.  The points are sorted once
    by Morton code at the finest level: every node and every sampling cell is
    then a run.  Each level works on the points still without a level only (a
    node's count is two binary searches in the sorted codes), so the deep
    levels cost what is left of the group, not the group.
    """
    n = len(q)
    code = morton(q, BITS)
    srt = np.argsort(code)  # ties (points of one finest cell) in any order: the choice does not depend on it
    code = code[srt]
    level = np.full(n, -1, dtype=np.int8)
    pos = np.arange(n)  # the points without a level yet, as positions in the sorted arrays (ascending)
    cells = [np.ascontiguousarray(q[srt, i]) for i in range(3)]
    at = np.asarray(index, dtype=np.int64)[srt]
    for d in range(cube.depth + 1):
        if not len(pos):
            break
        if d < group_level or d == cube.depth:
            sampled = np.full(len(pos), d < group_level)
        else:
            shift = 3 * (BITS - d)
            node = code[pos] >> shift
            first = np.flatnonzero(np.r_[True, node[1:] != node[:-1]])
            lo = node[first] << shift  # a node's codes are lo .. lo + 2**shift - 1 (no overflow at level 1)
            count = np.searchsorted(code, lo + ((1 << shift) - 1), side="right") - np.searchsorted(code, lo)
            sampled = np.repeat(count > cap, np.diff(np.r_[first, len(node)]))
        level[pos[~sampled]] = d
        pos = pos[sampled]
        if len(pos):
            chosen = _nearest_per_cell(code[pos], [c[pos] for c in cells], at[pos], BITS - d - cube.grid_bits)
            level[pos[chosen]] = d
            pos = np.delete(pos, chosen)
    out = np.empty(n, dtype=np.int8)
    out[srt] = level
    return out


def _nearest_per_cell(code: np.ndarray, q: list[np.ndarray], index: np.ndarray, fine: int) -> np.ndarray:
    """Positions of the chosen point of each sampling cell (cells of ``fine`` bits of ``q``, its three axes;
    ``code`` sorted): the one nearest the cell centre, ties to the smallest ``index``."""
    cell = code >> (3 * fine)
    dist = np.zeros(len(cell), dtype=np.int64)
    for axis in q:
        off = 2 * (axis & ((1 << fine) - 1)) + 1 - (1 << fine)  # twice the offset from the cell centre
        dist += off * off
    seg = np.flatnonzero(np.r_[True, cell[1:] != cell[:-1]])
    sizes = np.diff(np.r_[seg, len(cell)])
    low = int(index.min()) if len(index) else 0
    span = int(index.max()) - low + 1 if len(index) else 1
    if int(dist.max(initial=0)) < (1 << 62) // span:  # distance and index as one key: one reduction
        key = dist * span + (index - low)
        return np.flatnonzero(key == np.repeat(np.minimum.reduceat(key, seg), sizes))
    nearest = dist == np.repeat(np.minimum.reduceat(dist, seg), sizes)
    idx = np.where(nearest, index, np.iinfo(np.int64).max)
    return np.flatnonzero(nearest & (index == np.repeat(np.minimum.reduceat(idx, seg), sizes)))


def node_order(q: np.ndarray, level: np.ndarray, index: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points sorted by node (level, then x, y, z) and by point index in a node: ``(order, node starts, keys)``
    with ``keys`` ``(nodes, 4)`` as ``(level, x, y, z)``."""
    if not len(q):
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 4), np.int64)
    lv = level.astype(np.int64)
    key = pack(q >> (BITS - lv)[:, None])
    order = np.lexsort((index, key, lv))
    k, lvs = key[order], lv[order]
    starts = np.flatnonzero(np.r_[True, (k[1:] != k[:-1]) | (lvs[1:] != lvs[:-1])])
    keys = np.column_stack([lvs[starts], unpack(k[starts])])
    return order, starts, keys
