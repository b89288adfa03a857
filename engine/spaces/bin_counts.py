"""A tile's points counted per (u bin, v bin, storey, band): what the building's histogram passes read.

Once the storeys and their upper bands are known, every histogram pass of the
building's slicing and merging needs of a point only its ``(bu, bv)`` bins, its
storey and its band (:mod:`engine.spaces.histograms`).  Points of one 1 cm column
of a wall share all four, so a tile's distinct combinations, with their point
counts (:class:`BinCounts`), are about a third as many as its points (3.3 on the
600 m² ``bench_run`` building: walls collapse, floors and ceilings do not).  They are
counted once per tile (:func:`count_tile`) and kept where they were made, on the
workers (:class:`CountedStore`); each later pass reads them instead of reading and
binning the tile's points again, and weighs each entry by its count.  A pass sums
integer counts, so its histograms are exactly those of the points.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

# The grids and storey indexes here are engine.spaces.histograms's Grid and BoxIndex, which reads this module.
Grid = Any
BoxIndex = Any

#: A tile's distinct keys are counted in one dense ``np.bincount`` when its key range is at most this many
#: times its points (and at most :data:`DENSE_MAX` keys); a sort (``np.unique``) otherwise.
DENSE_PER_POINT = 4
DENSE_MAX = 1 << 26


@dataclass
class BinCounts:
    """One tile's distinct ``(bu, bv, storey, band)`` and how many points have each (sorted by that key).

    ``storey`` is the row of :class:`engine.spaces.histograms.BoxIndex`'s tables (``len(floors)``: no storey);
    ``band`` is 1 at or above the storey's upper-band z bin.  ``grid``, ``floors`` and ``band_z`` are what
    they were counted with (:meth:`check`).
    """

    bu: np.ndarray  # int32
    bv: np.ndarray  # int32
    storey: np.ndarray  # int16
    band: np.ndarray  # int8
    count: np.ndarray  # int32
    grid: Any
    floors: np.ndarray
    band_z: np.ndarray

    @property
    def points(self) -> int:
        return int(self.count.sum())

    def check(self, grid: Grid, index: BoxIndex, band_z: np.ndarray) -> None:
        """Raise ``ValueError`` unless these counts were made in ``grid`` with ``index``'s storeys and ``band_z``."""
        if not (_grid_key(self.grid) == _grid_key(grid) and np.array_equal(self.floors, index.floors)
                and np.array_equal(self.band_z, np.asarray(band_z, dtype=np.int64))):
            raise ValueError("a tile's bin counts were made with other storeys, bands or grid than this pass's")


def _grid_key(grid: Grid) -> tuple[float, ...]:
    """What a grid's bins depend on, as plain floats."""
    return (float(grid.frame.yaw), *map(float, grid.frame.origin), grid.bin_width, grid.z_bin, *map(float, grid.shift))


def count_tile(tile: str, store, grid: Grid, index: BoxIndex, band_z: np.ndarray) -> BinCounts:
    """:class:`BinCounts` of one tile (``index`` gives the storeys; its boxes are not used)."""
    band_z = np.asarray(band_z, dtype=np.int64)
    bu, bv, f, band, _ = tile_columns(tile, store, grid, index, band_z)  # the points themselves
    if len(bu) == 0:
        z = np.zeros(0, np.int32)
        return BinCounts(z, z, z.astype(np.int16), z.astype(np.int8), z, grid, index.floors, band_z)
    u0, v0, f0 = int(bu.min()), int(bv.min()), int(f.min())
    nv, nf = int(bv.max()) - v0 + 1, int(f.max()) - f0 + 1
    size = (int(bu.max()) - u0 + 1) * nv * nf * 2
    key = bu - u0
    key *= nv
    key += bv
    key -= v0
    key *= nf
    key += f
    key -= f0
    key *= 2
    key += band
    if size <= min(DENSE_PER_POINT * len(key), DENSE_MAX):
        counts = np.bincount(key, minlength=size)
        keys = np.flatnonzero(counts)
        count = counts[keys]
    else:
        keys, count = np.unique(key, return_counts=True)
    rest, b = np.divmod(keys, 2)
    rest, fr = np.divmod(rest, nf)
    ur, vr = np.divmod(rest, nv)
    return BinCounts((ur + u0).astype(np.int32), (vr + v0).astype(np.int32), (fr + f0).astype(np.int16),
                     b.astype(np.int8), count.astype(np.int32), grid, index.floors, band_z)


class CountedStore:
    """A tile store seen through its tiles' :class:`BinCounts`, for the building's histogram passes.

    With a client, each tile's counts are made by a task and stay on its worker
    (futures); a pass's task for a tile takes them as its input (:meth:`task_input`,
    as :class:`engine.spaces.memory_store.PieceStore`), so dask runs it where they
    are.  Without one they are made here, when first asked for, and kept
    (:meth:`counted`).  :meth:`release` lets them go.  The store pickles to the
    underlying store alone.
    """

    def __init__(self, store, grid: Grid, index: BoxIndex, band_z: np.ndarray, client=None,
                 tiles: list[str] | None = None) -> None:
        self.store = store
        self.grid, self.index = grid, index
        self.band_z = np.asarray(band_z, dtype=np.int64)
        self._futures: dict[str, Any] = {}
        self._kept: dict[str, BinCounts] = {}
        if client is not None:
            from engine import config

            names = list(tiles) if tiles is not None else [t.name for t in store.tiles]
            # a store whose tiles live on the workers (PieceStore) gives each tile's data as its task's input
            source = getattr(store, "task_input", None)
            inputs = [source(n) for n in names] if source is not None else names
            futures = client.map(count_tile, inputs, store=store, grid=grid, index=index, band_z=self.band_z,
                                 pure=False, retries=config.setting("retries"))
            self._futures = dict(zip(names, futures))

    @property
    def tiles(self):
        return self.store.tiles

    @property
    def meta(self):
        return self.store.meta

    def __getstate__(self) -> dict[str, Any]:
        return {"store": self.store, "grid": self.grid, "index": self.index, "band_z": self.band_z}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._futures, self._kept = {}, {}

    def task_input(self, tile: str):
        """What a pass's task gets for ``tile`` on a cluster: the future of its counts."""
        return self._futures[tile]

    def counted(self, tile: str) -> BinCounts:
        """The counts of ``tile``, made here (kept for the next pass)."""
        if tile not in self._kept:
            self._kept[tile] = count_tile(tile, self.store, self.grid, self.index, self.band_z)
        return self._kept[tile]

    def release(self) -> None:
        """Forget every tile's counts (on the workers too)."""
        for f in self._futures.values():
            f.release()
        self._futures, self._kept = {}, {}


def tile_columns(tile: Any, store, grid: Grid, index: BoxIndex, band_z: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """``(bu, bv, storey, band, weight)`` of what a pass counts in ``tile``: its :class:`BinCounts` (``tile``
    itself, or made by a :class:`CountedStore`), weighted by their counts; else its points (``weight`` None)."""
    if isinstance(tile, BinCounts) or hasattr(store, "counted"):
        t = tile if isinstance(tile, BinCounts) else store.counted(tile)
        t.check(grid, index, band_z)
        return (t.bu.astype(np.int64), t.bv.astype(np.int64), t.storey.astype(np.int64), t.band, t.count)
    bu, bv, bz = grid.tile_bins(store, tile)
    f = index.storey_rows(bz)
    return bu, bv, f, index.band_of(f, bz, band_z), None
