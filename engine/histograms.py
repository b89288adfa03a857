"""The per-tile histogram passes of space parsing: one bincount per tile, summed across tiles.

Every point gets integer bins in the aligned frame (:class:`Grid`): ``bu``,
``bv`` along the two horizontal axes and ``bz`` along z, all ``floor(coordinate
/ bin)``, computed the same way in every pass so that boxes given in bins hold
exactly the points they held when they were cut.

A pass maps a task over the tiles; each task locates its points in the current
boxes (:class:`BoxIndex`: storeys, then slices and cells), keys every point by
``(segment, band, bin)`` and counts all keys with ONE ``np.bincount``; ``band``
is 1 for points in the storey's upper band (above door height), so that each
segment gets both its all-heights and its upper-band histogram.  A tile only
touches a few segments and a few hundred bins, so its result is a small dense
block ``(present segments) x (the tile's bin range)`` (:class:`SparseHist`); the
driver adds the blocks into one histogram per segment (:func:`accumulate`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.alignment import Frame


@dataclass(frozen=True)
class Grid:
    """Integer bins of the aligned frame.

    ``bu = floor(u / bin_width)``, ``bv = floor(v / bin_width)``, ``bz = floor(z /
    z_bin)`` with ``(u, v, z)`` aligned coordinates (relative to ``frame.origin``).
    ``shift`` is ``frame.origin - store origin`` (tile coordinates are local to the
    store's origin).
    """

    frame: Frame
    bin_width: float
    z_bin: float
    shift: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @classmethod
    def for_store(cls, store, frame: Frame, bin_width: float, z_bin: float | None = None) -> "Grid":
        shift = tuple(float(a - b) for a, b in zip(frame.origin, store.meta.origin))
        return cls(frame, float(bin_width), float(z_bin or bin_width), shift)

    def aligned(self, xyz_local: np.ndarray) -> np.ndarray:
        """Store-local coordinates -> aligned ``(u, v, z)`` (float64)."""
        rel = xyz_local - np.asarray(self.shift) if any(self.shift) else xyz_local
        return self.frame.rotate_to_aligned(rel)

    def bins(self, xyz_local: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(bu, bv, bz)`` int64 of store-local points."""
        a = self.aligned(xyz_local)
        bu = np.floor(a[:, 0] / self.bin_width).astype(np.int64)
        bv = np.floor(a[:, 1] / self.bin_width).astype(np.int64)
        bz = np.floor(a[:, 2] / self.z_bin).astype(np.int64)
        return bu, bv, bz

    def tile_bins(self, store, tile) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.bins(store.xyz(tile))


@dataclass
class BoxIndex:
    """Locates points in disjoint boxes: storeys in z, then boxes in (u, v) bins per storey.

    ``floors``: ``(F, 2)`` z-bin ranges ``[z0, z1)``; ``boxes``: ``(B, 5)`` rows
    ``[floor, u0, u1, v0, v1]`` (half-open bin ranges).  Per storey the sorted
    distinct box boundaries split the plane into blocks (the arrangement), and a
    table maps each block to its box, so locating a point is two
    ``searchsorted`` on short arrays and a table look-up.
    """

    floors: np.ndarray
    boxes: np.ndarray
    ub: list[np.ndarray]
    vb: list[np.ndarray]
    table: list[np.ndarray]

    @classmethod
    def build(cls, floors: np.ndarray, boxes: np.ndarray) -> "BoxIndex":
        floors = np.asarray(floors, dtype=np.int64).reshape(-1, 2)
        boxes = np.asarray(boxes, dtype=np.int64).reshape(-1, 5)
        ubs, vbs, tables = [], [], []
        for f in range(len(floors)):
            rows = np.flatnonzero(boxes[:, 0] == f)
            b = boxes[rows]
            ub = np.unique(np.concatenate([b[:, 1], b[:, 2]])) if len(b) else np.zeros(0, np.int64)
            vb = np.unique(np.concatenate([b[:, 3], b[:, 4]])) if len(b) else np.zeros(0, np.int64)
            t = np.full((max(len(ub) - 1, 0), max(len(vb) - 1, 0)), -1, dtype=np.int64)
            if len(b):
                iu0, iu1 = np.searchsorted(ub, b[:, 1]), np.searchsorted(ub, b[:, 2])
                iv0, iv1 = np.searchsorted(vb, b[:, 3]), np.searchsorted(vb, b[:, 4])
                for k, r in enumerate(rows):
                    t[iu0[k]:iu1[k], iv0[k]:iv1[k]] = r
            ubs.append(ub)
            vbs.append(vb)
            tables.append(t)
        return cls(floors, boxes, ubs, vbs, tables)

    def floor_of(self, bz: np.ndarray) -> np.ndarray:
        """Storey of each z bin, -1 outside every storey."""
        if len(self.floors) == 0:
            return np.full(len(bz), -1, dtype=np.int64)
        order = np.argsort(self.floors[:, 0], kind="stable")
        z0 = self.floors[order, 0]
        k = np.searchsorted(z0, bz, side="right") - 1
        f = np.where(k >= 0, order[np.clip(k, 0, None)], -1)
        inside = (f >= 0) & (bz < self.floors[np.clip(f, 0, None), 1])
        return np.where(inside, f, -1)

    def blocks(self, bu: np.ndarray, bv: np.ndarray, bz: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(floor, iu, iv, box)`` of each point; -1 where a point lies in no box."""
        n = len(bu)
        floor = self.floor_of(bz)
        iu = np.full(n, -1, dtype=np.int64)
        iv = np.full(n, -1, dtype=np.int64)
        box = np.full(n, -1, dtype=np.int64)
        for f in range(len(self.floors)):
            sel = np.flatnonzero(floor == f)
            ub, vb, t = self.ub[f], self.vb[f], self.table[f]
            if len(sel) == 0 or t.size == 0:
                continue
            a = np.searchsorted(ub, bu[sel], side="right") - 1
            b = np.searchsorted(vb, bv[sel], side="right") - 1
            ok = (a >= 0) & (a < t.shape[0]) & (b >= 0) & (b < t.shape[1])
            s = sel[ok]
            iu[s], iv[s] = a[ok], b[ok]
            box[s] = t[a[ok], b[ok]]
        return floor, iu, iv, box

    def locate(self, bu: np.ndarray, bv: np.ndarray, bz: np.ndarray) -> np.ndarray:
        """Box of each point, -1 outside every box."""
        return self.blocks(bu, bv, bz)[3]


@dataclass
class SparseHist:
    """One tile's counts: ``counts[k, j]`` points of segment ``segments[k]`` in bin ``lo + j``."""

    segments: np.ndarray
    lo: int
    counts: np.ndarray


def keyed_histogram(segment: np.ndarray, bins: np.ndarray) -> SparseHist:
    """Counts per ``(segment, bin)`` of the points with ``segment >= 0``, in ONE bincount."""
    keep = segment >= 0
    seg, b = segment[keep], bins[keep]
    if len(seg) == 0:
        return SparseHist(np.zeros(0, np.int64), 0, np.zeros((0, 0), np.int64))
    present = np.flatnonzero(np.bincount(seg))
    rank = np.zeros(int(present[-1]) + 1, dtype=np.int64)
    rank[present] = np.arange(len(present))
    lo, hi = int(b.min()), int(b.max())
    width = hi - lo + 1
    counts = np.bincount(rank[seg] * width + (b - lo), minlength=len(present) * width)
    return SparseHist(present, lo, counts.reshape(len(present), width))


def accumulate(parts: list[SparseHist], lo: np.ndarray, length: np.ndarray) -> list[np.ndarray]:
    """Sum tile blocks into one histogram per segment: segment ``s`` covers bins ``[lo[s], lo[s] + length[s])``.

    Counts outside a segment's range (there should be none) are dropped.
    """
    out = [np.zeros(int(n), dtype=np.int64) for n in length]
    for part in parts:
        for k, s in enumerate(part.segments):
            a = part.lo - int(lo[s])
            row = part.counts[k]
            i0, i1 = max(a, 0), min(a + len(row), len(out[s]))
            if i1 > i0:
                out[s][i0:i1] += row[i0 - a:i1 - a]
    return out


# -- the passes (one task per tile) -------------------------------------------------------------

def z_histogram(bz: np.ndarray, lo: int, n: int) -> np.ndarray:
    """Counts of z bins ``[lo, lo + n)``; bins outside are clipped to the ends."""
    return np.bincount(np.clip(bz - lo, 0, n - 1), minlength=n)


def upper_band(floor: np.ndarray, bz: np.ndarray, band_z: np.ndarray) -> np.ndarray:
    """1 for points at or above their storey's upper-band z bin (above door height), else 0."""
    if len(band_z) == 0:
        return np.zeros(len(bz), dtype=np.int64)
    return (bz >= band_z[np.clip(floor, 0, None)]).astype(np.int64)


def segment_histograms(tile: str, store, grid: Grid, index: BoxIndex, active: np.ndarray, axis: int,
                       band_z: np.ndarray) -> SparseHist:
    """One tile's histograms along ``axis`` (0: u, 1: v) of every active box, keyed by (box, band, bin).

    Key ``2 * box + band`` where band 1 marks the storey's upper band (see :func:`upper_band`).
    """
    bu, bv, bz = grid.tile_bins(store, tile)
    floor, _, _, box = index.blocks(bu, bv, bz)
    on = (box >= 0) & active[np.clip(box, 0, None)]
    key = np.where(on, 2 * box + upper_band(floor, bz, band_z), -1)
    return keyed_histogram(key, bu if axis == 0 else bv)


@dataclass
class EdgeTables:
    """For every block of the cells' arrangement and each side (-u, +u, -v, +v): the edge there, or -1.

    ``position[e]`` is the bin edge of the shared face of edge ``e`` along its
    axis ``axis[e]``; a point within ``window`` bins of a face (on either side)
    is counted in that edge's histogram at ``window + (bin - position)``.
    """

    tables: list[np.ndarray]  # per storey (nu, nv, 4)
    axis: np.ndarray
    position: np.ndarray
    window: int


def edge_histograms(tile: str, store, grid: Grid, index: BoxIndex, edges: EdgeTables,
                    band_z: np.ndarray) -> SparseHist:
    """One tile's histograms across every shared face of neighbouring cells (merging, section 3.1.2).

    Each point counts in the edges of its block's four sides whose face lies
    within the window; all of them go to ONE bincount keyed by ``2 * edge + band``.
    """
    bu, bv, bz = grid.tile_bins(store, tile)
    floor, iu, iv, box = index.blocks(bu, bv, bz)
    band = upper_band(floor, bz, band_z)
    keys_e, keys_b = [], []
    inside = np.flatnonzero(box >= 0)
    w = edges.window
    for f in np.unique(floor[inside]):
        sel = inside[floor[inside] == f]
        t = edges.tables[f]
        for side in range(4):
            e = t[iu[sel], iv[sel], side]
            ok = e >= 0
            if not ok.any():
                continue
            pts = sel[ok]
            e = e[ok]
            off = (bu if side < 2 else bv)[pts] - edges.position[e]
            near = (off >= -w) & (off < w)
            keys_e.append(2 * e[near] + band[pts[near]])
            keys_b.append(off[near] + w)
    if not keys_e:
        return keyed_histogram(np.zeros(0, np.int64), np.zeros(0, np.int64))
    return keyed_histogram(np.concatenate(keys_e), np.concatenate(keys_b))
