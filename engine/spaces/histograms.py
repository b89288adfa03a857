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
Once the storeys are known the passes read each tile's points counted per
``(bu, bv, storey, band)`` (:mod:`engine.spaces.bin_counts`) instead of the points.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.spaces.alignment import Frame
from engine.spaces.bin_counts import tile_columns
from tiles.tasks import run_tasks


@dataclass(frozen=True)
class Grid:
    """Integer bins of the aligned frame.

    ``bu = floor(u / bin_width)``, ``bv = floor(v / bin_width)``, ``bz = floor(z /
    z_bin)`` with ``(u, v, z)`` aligned coordinates (relative to ``frame.origin``),
    computed from the stored scaled integers by :meth:`raw_bins`.  ``shift`` is
    ``frame.origin - store origin`` (for :meth:`aligned` on store-local coordinates).
    """

    frame: Frame
    bin_width: float
    z_bin: float
    shift: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @classmethod
    def for_store(cls, store, frame: Frame, bin_width: float, z_bin: float | None = None) -> Grid:
        shift = tuple(float(a - b) for a, b in zip(frame.origin, store.meta.origin))
        return cls(frame, float(bin_width), float(z_bin or bin_width), shift)

    def aligned(self, xyz_local: np.ndarray) -> np.ndarray:
        """Store-local coordinates -> aligned ``(u, v, z)`` (float64)."""
        rel = xyz_local - np.asarray(self.shift) if any(self.shift) else xyz_local
        return self.frame.rotate_to_aligned(rel)

    def raw_affine(self, meta) -> np.ndarray:
        """``(3, 3)`` rows ``[a_x, a_y, a_0]``: bin coordinate = a_x * raw_x + a_y * raw_y + a_0 (u, v), z alike.

        The stored coordinates are scaled integers (``world = raw * scale + offset``),
        so the bins are one affine map of them; every pass uses this one map
        (:meth:`raw_bins`), so a point always falls in the same bin.
        """
        c, s = self.frame.cos_sin
        sx, sy, sz = meta.scale
        bx, by, bz = (np.asarray(meta.offset) - np.asarray(self.frame.origin)).tolist()
        w, zb = self.bin_width, self.z_bin
        return np.array([[c * sx / w, s * sy / w, (c * bx + s * by) / w],
                         [-s * sx / w, c * sy / w, (-s * bx + c * by) / w],
                         [0.0, sz / zb, bz / zb]])

    def raw_bins(self, raw: dict[str, np.ndarray], affine: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(bu, bv, bz)`` int64 of raw scaled-integer coordinates (see :meth:`raw_affine`)."""
        x = raw["x"].astype(np.float64)
        y = raw["y"].astype(np.float64)
        out = []
        for k in range(2):
            t = x * affine[k, 0]
            t += y * affine[k, 1]
            t += affine[k, 2]
            np.floor(t, out=t)
            out.append(t.astype(np.int64))
        t = raw["z"].astype(np.float64)
        t *= affine[2, 1]
        t += affine[2, 2]
        np.floor(t, out=t)
        return out[0], out[1], t.astype(np.int64)

    def tile_bins(self, store, tile) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(bu, bv, bz)`` of every point of a tile (a store that keeps its bins, such as the in-memory store
        of a refined space, :class:`engine.spaces.memory_store.MemoryStore`, hands out its read-only copy)."""
        cached = getattr(store, "cached_bins", None)
        if cached is not None:
            return cached(self, tile)
        return self.raw_bins(store.read(tile, ("x", "y", "z")), self.raw_affine(store.meta))

    def tile_z_bins(self, raw_z: np.ndarray, meta) -> np.ndarray:
        """``bz`` alone (it does not depend on the yaw), the same map as :meth:`tile_bins`."""
        a = self.raw_affine(meta)
        t = raw_z.astype(np.float64)
        t *= a[2, 1]
        t += a[2, 2]
        np.floor(t, out=t)
        return t.astype(np.int64)


def tiles_by_size(store) -> list[str]:
    """Tile names, largest first: submitted in that order, a pass ends with small tasks (better balance)."""
    return [t.name for t in sorted(store.tiles, key=lambda t: (-t.count, t.name))]


def tile_extents(store, grid: Grid) -> np.ndarray:
    """Per tile ``[u0, u1, v0, v1, z0, z1]`` in bins, a conservative bound from its world bounds."""
    o = np.asarray(store.meta.origin)
    out = []
    for t in store.tiles:
        x0, y0, z0, x1, y1, z1 = t.bounds
        corners = np.array([[x0, y0, z0], [x0, y1, z0], [x1, y0, z1], [x1, y1, z1]]) - o
        a = grid.aligned(corners)
        out.append([np.floor(a[:, 0].min() / grid.bin_width) - 1, np.floor(a[:, 0].max() / grid.bin_width) + 2,
                    np.floor(a[:, 1].min() / grid.bin_width) - 1, np.floor(a[:, 1].max() / grid.bin_width) + 2,
                    np.floor(a[:, 2].min() / grid.z_bin) - 1, np.floor(a[:, 2].max() / grid.z_bin) + 2])
    return np.array(out, dtype=np.int64).reshape(-1, 6)


def tiles_touching(extents: np.ndarray, floors: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Which tiles (rows of :func:`tile_extents`) overlap at least one of the boxes ``[floor, u0, u1, v0, v1]``."""
    if len(boxes) == 0:
        return np.zeros(len(extents), dtype=bool)
    b = np.asarray(boxes, dtype=np.int64)
    fz = np.asarray(floors, dtype=np.int64)[b[:, 0]]
    e = extents[:, None, :]
    hit = ((e[..., 0] < b[:, 2]) & (e[..., 1] > b[:, 1]) & (e[..., 2] < b[:, 4]) & (e[..., 3] > b[:, 3])
           & (e[..., 4] < fz[:, 1]) & (e[..., 5] > fz[:, 0]))
    return hit.any(axis=1)


def share(client, obj):
    """``obj`` for the tasks of a batch: sent once to every worker (a future), or itself without a client."""
    if client is None:
        return obj
    return client.scatter(obj, broadcast=True, hash=False)


@dataclass
class BoxIndex:
    """Locates points in disjoint boxes: storeys in z, then boxes in (u, v) bins per storey.

    ``floors``: ``(F, 2)`` z-bin ranges ``[z0, z1)``; ``boxes``: ``(B, 5)`` rows
    ``[floor, u0, u1, v0, v1]`` (half-open bin ranges).  Per storey the sorted
    distinct box boundaries ``ub``, ``vb`` split the plane into blocks (the
    arrangement) and ``table[f]`` maps each block to its box.  Locating a point
    is four gathers in flat look-up tables (z bin -> storey, (storey, u bin) ->
    block row offset, (storey, v bin) -> block column, block -> box), the same
    for all storeys at once: no search, no mask, no loop over storeys.
    """

    floors: np.ndarray
    boxes: np.ndarray
    ub: list[np.ndarray]
    vb: list[np.ndarray]
    table: list[np.ndarray]
    # flat look-up tables (built by build): see _flatten
    z0: int = 0
    ztab: np.ndarray | None = None
    umin: int = 0
    nu: int = 0
    ubase: np.ndarray | None = None
    vmin: int = 0
    nvb: int = 0
    vcol: np.ndarray | None = None
    flat: np.ndarray | None = None

    @classmethod
    def build(cls, floors: np.ndarray, boxes: np.ndarray) -> BoxIndex:
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
        idx = cls(floors, boxes, ubs, vbs, tables)
        idx._flatten()
        return idx

    def _flatten(self) -> None:
        """Flat tables so that a point's block is ``ubase[f, bu] + vcol[f, bv]`` (negative: none).

        ``ztab`` maps a z bin to its storey (the extra storey ``F`` is "none");
        ``ubase[f, u]`` is the offset of the row of block column ``u`` of storey
        ``f`` in ``flat``; ``vcol[f, v]`` is the block row.  Both tables have one
        padding column at each end and a last row for "no storey", all holding a
        large negative number, so out-of-range bins need no masks, only a clip.
        """
        nf = len(self.floors)
        neg = -(1 << 40)
        if nf:
            self.z0 = int(self.floors[:, 0].min()) - 1
            self.ztab = np.full(int(self.floors[:, 1].max()) - self.z0 + 1, nf, dtype=np.int64)
            for f, (a, b) in enumerate(self.floors):
                self.ztab[a - self.z0:b - self.z0] = f
        else:
            self.z0, self.ztab = 0, np.zeros(1, dtype=np.int64)
        ub_all = [u for u in self.ub if len(u)]
        vb_all = [v for v in self.vb if len(v)]
        self.umin = int(min(u[0] for u in ub_all)) - 1 if ub_all else 0
        self.nu = int(max(u[-1] for u in ub_all)) - self.umin + 1 if ub_all else 1
        self.vmin = int(min(v[0] for v in vb_all)) - 1 if vb_all else 0
        self.nvb = int(max(v[-1] for v in vb_all)) - self.vmin + 1 if vb_all else 1
        ubase = np.full((nf + 1, self.nu + 2), neg, dtype=np.int64)
        vcol = np.full((nf + 1, self.nvb + 2), neg, dtype=np.int64)
        toff = np.concatenate(([0], np.cumsum([t.size for t in self.table]))).astype(np.int64)
        for f in range(nf):
            ub, vb, t = self.ub[f], self.vb[f], self.table[f]
            if t.size == 0:
                continue
            us = np.arange(ub[0], ub[-1])
            iu = np.searchsorted(ub, us, side="right") - 1
            ubase[f, us - self.umin + 1] = toff[f] + iu * t.shape[1]
            vs = np.arange(vb[0], vb[-1])
            vcol[f, vs - self.vmin + 1] = np.searchsorted(vb, vs, side="right") - 1
        self.ubase, self.vcol = ubase.ravel(), vcol.ravel()
        self.flat = np.concatenate([t.ravel() for t in self.table] + [np.full(1, -1, np.int64)])

    def floor_of(self, bz: np.ndarray) -> np.ndarray:
        """Storey of each z bin, -1 outside every storey."""
        f = self.ztab[np.clip(bz - self.z0, 0, len(self.ztab) - 1)]
        return np.where(f < len(self.floors), f, -1)

    def band_of(self, f: np.ndarray, bz: np.ndarray, band_z: np.ndarray) -> np.ndarray:
        """1 for points at or above their storey's upper-band z bin (``f``: storey rows of :meth:`blocks`)."""
        return (bz >= np.append(np.asarray(band_z, np.int64), np.iinfo(np.int64).max)[f]).view(np.int8)

    def storey_rows(self, bz: np.ndarray) -> np.ndarray:
        """Row of each z bin's storey in the tables (``len(floors)``: none)."""
        f = bz - self.z0
        np.clip(f, 0, len(self.ztab) - 1, out=f)
        return self.ztab[f]

    def block_in_storey(self, bu: np.ndarray, bv: np.ndarray, f: np.ndarray) -> np.ndarray:
        """Flat block index of each point of storey row ``f`` (:meth:`storey_rows`; negative: in no box's range)."""
        ui = np.subtract(bu, self.umin - 1, dtype=np.int64)
        np.clip(ui, 0, self.nu + 1, out=ui)
        ui += f * (self.nu + 2)
        vi = np.subtract(bv, self.vmin - 1, dtype=np.int64)
        np.clip(vi, 0, self.nvb + 1, out=vi)
        vi += f * (self.nvb + 2)
        blk = self.ubase[ui]
        blk += self.vcol[vi]
        return blk

    def box_of_block(self, blk: np.ndarray) -> np.ndarray:
        """Box of each flat block index (-1: none)."""
        return self.flat[np.where(blk >= 0, blk, len(self.flat) - 1)]

    def block_of(self, bu: np.ndarray, bv: np.ndarray, bz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Flat block index of each point in the storeys' arrangements (negative: outside every box's
        range) and its storey row in the tables (``len(floors)``: none)."""
        f = self.storey_rows(bz)
        return self.block_in_storey(bu, bv, f), f

    def blocks(self, bu: np.ndarray, bv: np.ndarray, bz: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(block, box, storey)`` of each point: flat block index (negative: none), box (-1: none) and
        storey (``len(floors)``: none)."""
        blk, f = self.block_of(bu, bv, bz)
        return blk, self.box_of_block(blk), f

    def locate(self, bu: np.ndarray, bv: np.ndarray, bz: np.ndarray) -> np.ndarray:
        """Box of each point, -1 outside every box."""
        return self.blocks(bu, bv, bz)[1]


@dataclass
class SparseHist:
    """One tile's counts: ``counts[k, j]`` points of segment ``segments[k]`` in bin ``lo + j``."""

    segments: np.ndarray
    lo: int
    counts: np.ndarray


def keyed_histogram(segment: np.ndarray, bins: np.ndarray, weights: np.ndarray | None = None) -> SparseHist:
    """Counts per ``(segment, bin)`` of the points with ``segment >= 0``, in ONE bincount.

    Points with a negative segment go to a trash row that is dropped, so no
    point is copied out; the bins span the tile's own range of ``bins``.
    ``weights``: integer point counts of each entry (:class:`engine.spaces.bin_counts.BinCounts`; None: one each).
    """
    if len(segment) == 0:
        return SparseHist(np.zeros(0, np.int64), 0, np.zeros((0, 0), np.int64))
    seg1 = np.maximum(segment, -1)
    seg1 += 1  # 0: trash
    per = np.bincount(seg1)
    present = np.flatnonzero(per[1:])
    if len(present) == 0:
        return SparseHist(np.zeros(0, np.int64), 0, np.zeros((0, 0), np.int64))
    rank = np.full(len(per), len(present), dtype=np.int64)
    rank[present + 1] = np.arange(len(present))
    lo, hi = int(bins.min()), int(bins.max())
    width = hi - lo + 1
    key = rank[seg1]
    key *= width
    key += bins
    key -= lo
    counts = np.bincount(key, weights=weights, minlength=(len(present) + 1) * width)
    if weights is not None:  # sums of integer counts, exact in float64 below 2**53
        counts = np.rint(counts).astype(np.int64)
    return SparseHist(present, lo, counts.reshape(len(present) + 1, width)[:-1])


def accumulate(parts: list[SparseHist], lo: np.ndarray, length: np.ndarray,
               out: list[np.ndarray] | None = None) -> list[np.ndarray]:
    """Sum tile blocks into one histogram per segment: segment ``s`` covers bins ``[lo[s], lo[s] + length[s])``.

    Adds into ``out`` when given (a running sum over batches of tiles).  Counts
    outside a segment's range (there should be none) are dropped.
    """
    if out is None:
        out = [np.zeros(int(n), dtype=np.int64) for n in length]
    for part in parts:
        for k, s in enumerate(part.segments):
            a = part.lo - int(lo[s])
            row = part.counts[k]
            i0, i1 = max(a, 0), min(a + len(row), len(out[s]))
            if i1 > i0:
                out[s][i0:i1] += row[i0 - a:i1 - a]
    return out


def histogram_pass(fn, tiles: list[str], lo: np.ndarray, length: np.ndarray, *, client=None, label: str,
                   extra_args: tuple = ()) -> list[np.ndarray]:
    """Run a per-tile histogram task over the tiles and sum the blocks, batch by batch.

    The driver holds one batch of tile results at a time (``buildingparser.spaces.batch-tiles``
    tiles), so its memory does not grow with the building.  A store (``extra_args[0]``) whose tiles'
    data are futures on the workers (:class:`engine.spaces.memory_store.PieceStore`) gives them as the tasks'
    inputs (``task_input``), so that each task runs where its data is.
    """
    from engine import config

    batch = config.setting("spaces.batch-tiles")
    out = [np.zeros(int(n), dtype=np.int64) for n in length]
    task_input = getattr(extra_args[0], "task_input", None) if extra_args and client is not None else None
    for start in range(0, len(tiles), batch):
        part_tiles = list(tiles[start:start + batch])
        inputs = [task_input(t) for t in part_tiles] if task_input is not None else part_tiles
        parts = run_tasks(fn, inputs, client=client, label=label, keys=part_tiles, extra_args=extra_args)
        accumulate(parts, lo, length, out)
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


def segment_histograms(tile: str, store, grid: Grid, index: BoxIndex, axis_of: np.ndarray, both: np.ndarray,
                       band_z: np.ndarray) -> SparseHist:
    """One tile's histograms of the boxes being searched, all in ONE bincount.

    Box ``b`` is histogrammed along its axis ``axis_of[b]`` (0: u, 1: v; -1: not
    searched) and, when ``both[b]``, along the other axis too.  Key
    ``4 * box + 2 * which + band``: ``which`` 0 for its axis, 1 for the other;
    ``band`` 1 for points in the storey's upper band (above door height).
    """
    bu, bv, f, band, weight = tile_columns(tile, store, grid, index, band_z)
    box = index.box_of_block(index.block_in_storey(bu, bv, f))
    axes = set(np.unique(axis_of[axis_of >= 0]).tolist())
    key_of = np.append(np.where(axis_of >= 0, 4 * np.arange(len(axis_of)), -4), -4)
    key = key_of[box]  # box -1 (none) -> the last entry
    key += band
    if axes == {0}:
        first = bu
    elif axes == {1}:
        first = bv
    else:
        first = np.where(np.append(axis_of, 0)[box] == 1, bv, bu)
    if not both.any():
        return keyed_histogram(key, first, weight)
    sel = np.flatnonzero(np.append(both, False)[box])
    ax = np.append(axis_of, 0)[box[sel]]
    return keyed_histogram(np.concatenate([key, key[sel] + 2]),
                           np.concatenate([first, np.where(ax == 1, bu[sel], bv[sel])]),
                           None if weight is None else np.concatenate([weight, weight[sel]]))


@dataclass
class EdgeTables:
    """For every block of the cells' arrangement and each side (-u, +u, -v, +v): the edge there, or -1.

    ``flat[4 * block + side]`` with ``block`` the flat block index of
    :meth:`BoxIndex.block_index`.  ``position[e]`` is the bin edge of the shared
    face of edge ``e`` along its axis; a point within ``window`` bins of a face
    (on either side) is counted in that edge's histogram at ``window + (bin -
    position)``.
    """

    flat: np.ndarray
    axis: np.ndarray
    position: np.ndarray
    window: int


def edge_histograms(tile: str, store, grid: Grid, index: BoxIndex, edges: EdgeTables,
                    band_z: np.ndarray) -> SparseHist:
    """One tile's histograms across every shared face of neighbouring cells (merging, section 3.1.2).

    Each point counts in the edges of its block's four sides whose face lies
    within the window; all of them go to ONE bincount keyed by ``2 * edge + band``.
    """
    bu, bv, f, band, weight = tile_columns(tile, store, grid, index, band_z)
    blk = index.block_in_storey(bu, bv, f)
    inside = np.flatnonzero(index.box_of_block(blk) >= 0)
    band = band[inside].astype(np.int64)
    blk, bu, bv = blk[inside], bu[inside], bv[inside]
    weight = None if weight is None else weight[inside]
    w = edges.window
    # the four sides' edges of every point at once: (points, 4)
    e = edges.flat[(4 * blk)[:, None] + np.arange(4)]
    off = np.stack([bu, bu, bv, bv], axis=1)
    off -= edges.position[np.maximum(e, 0)]
    near = (e >= 0) & (off >= -w) & (off < w)
    rows = np.nonzero(near)[0]
    return keyed_histogram(2 * e[near] + band[rows], off[near] + w, None if weight is None else weight[rows])
