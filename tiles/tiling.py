"""Which tile a point falls in, ``floor((raw * scale + offset) / tile_size)`` in float64, with integer work per point.

:class:`TileGrid` is the tiling of a store's coordinate grid; the store builder
(:class:`tiles.builder.StoreBuilder`) is one, and sorts each part's points by
tile with :meth:`TileGrid.tile_order`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass
class TileOrder:
    """The stable order of a part's points by tile (:meth:`TileGrid.tile_order`)."""

    #: positions in the part, tile run after tile run
    order: np.ndarray
    #: per tile run: first position in ``order``, point count, tile indices
    starts: np.ndarray
    counts: np.ndarray
    ix: np.ndarray
    iy: np.ndarray


class TileGrid:
    """The tiles of a coordinate grid: ``world = raw * scale + offset`` per axis, square tiles of ``tile_size``
    metres.  Subclasses set the three attributes."""

    scale: list[float]
    offset: list[float]
    tile_size: float

    def tile_keys(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Tile indices of raw scaled-integer coordinates: ``floor((raw * scale + offset) / tile_size)``
        in float64 (the definition; :meth:`local_tile_index` computes the same faster)."""
        out = []
        for v, i in ((x, 0), (y, 1)):
            w = np.multiply(v, self.scale[i], dtype=np.float64)
            w += self.offset[i]
            w /= self.tile_size
            out.append(np.floor(w, out=w).astype(np.int64))
        return out[0], out[1]

    def _tile_of(self, raw: int, axis: int) -> int:
        """:meth:`tile_keys` of one raw integer (the same float64 operations, in Python floats)."""
        return math.floor((float(raw) * self.scale[axis] + self.offset[axis]) / self.tile_size)

    def local_tile_index(self, v: np.ndarray, axis: int) -> tuple[np.ndarray, int, int]:
        """The tile index along ``axis`` of every raw coordinate ``v``, as :meth:`tile_keys` gives it, but
        relative to the first tile: ``(index - first, first, count of tiles spanned)``.

        Computed from the exact thresholds (the smallest raw value of each tile
        after the first, found with the float formula, which is monotonic), so
        that the per-point work is integer: one ``floor_divide`` when the
        thresholds are evenly spaced (a tile is a whole number of raw steps),
        else a ``searchsorted``.
        """
        lo, hi = int(v.min()), int(v.max())
        first, last = self._tile_of(lo, axis), self._tile_of(hi, axis)
        m = last - first
        if m == 0:
            return np.zeros(len(v), dtype=np.uint16), first, 1
        if m >= 1 << 12:  # a part spanning thousands of tiles: the formula itself
            w = np.multiply(v, self.scale[axis], dtype=np.float64)
            w += self.offset[axis]
            w /= self.tile_size
            return (np.floor(w, out=w) - first).astype(np.int64), first, m + 1
        step = self.tile_size / self.scale[axis]
        thresholds = []
        for k in range(first + 1, last + 1):
            r = max(lo, min(hi, math.ceil((k * self.tile_size - self.offset[axis]) / self.scale[axis])))
            while r > lo and self._tile_of(r - 1, axis) >= k:
                r -= 1
            while self._tile_of(r, axis) < k:
                r += 1
            thresholds.append(r)
        t = np.asarray(thresholds, dtype=np.int64)
        q = int(t[1] - t[0]) if m > 1 else max(int(round(step)), 1)
        t0 = int(t[0])
        if (hi - lo < 1 << 30 and q > 0 and np.all(t == t0 + q * np.arange(m))
                and t0 - q <= lo and hi < t0 + q * m):
            idx = np.subtract(v, t0, dtype=np.int32) if v.dtype.itemsize <= 4 else v.astype(np.int64) - t0
            idx //= q
            idx += 1
            return idx.astype(np.uint16), first, m + 1
        return np.searchsorted(t, v, side="right").astype(np.uint16), first, m + 1

    def tile_order(self, x: np.ndarray, y: np.ndarray) -> TileOrder:
        """The stable order of points by tile, from their raw x and y (see :class:`TileOrder`)."""
        kx, x0, nx = self.local_tile_index(x, 0)
        ky, y0, ny = self.local_tile_index(y, 1)
        if nx * ny <= 1 << 16:
            key = kx.astype(np.uint16)
            key *= np.uint16(ny)  # < nx * ny: no overflow
            key += ky.astype(np.uint16, copy=False)
        else:
            key = kx.astype(np.int64) * ny + ky
        # numpy's stable sort of 16-bit keys is a radix sort: O(n) for parts spanning < 65536 tiles
        order = np.argsort(key, kind="stable")
        if nx * ny > max(1 << 16, 4 * len(key)):  # sparse: the occupied tiles, not every tile of the extent
            used, starts, counts = np.unique(key[order], return_index=True, return_counts=True)
            return TileOrder(order, starts, counts, x0 + used // ny, y0 + used % ny)
        per_key = np.bincount(key, minlength=nx * ny)
        used = np.flatnonzero(per_key)
        counts = per_key[used]
        return TileOrder(order, np.cumsum(per_key)[used] - counts, counts, x0 + used // ny, y0 + used % ny)
