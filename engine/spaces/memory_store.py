"""A tile store in memory: a refined space's points as a one-tile store, or as pieces held by the workers.

The refinement (:mod:`engine.spaces.refine`) reuses the store-based passes
unchanged through :class:`MemoryStore`, a one-tile store holding the space's raw
scaled integers (so a point falls in exactly the same bins here and when the
labels are written).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from engine.spaces.histograms import Grid


@dataclass
class MemoryTile:
    """The tile record the passes use: name, point count, world bounds."""

    name: str
    count: int
    bounds: list[float]


@dataclass
class MemoryMeta:
    """The store metadata the passes use (the real store's scale, offset and origin)."""

    scale: tuple[float, float, float]
    offset: tuple[float, float, float]
    origin: tuple[float, float, float]
    point_count: int
    bounds: list[float]


class MemoryStore:
    """A one-tile, read-only store of raw scaled-integer coordinates (``x``, ``y``, ``z``).

    It keeps the bins of its points in the last grid asked for (:meth:`cached_bins`):
    the refinement of a space makes one histogram pass over the same points per
    slicing level and one for its faces, all in the same frame, and computing the
    bins was about half of each pass (the medium bench_run building: 6 passes over
    5.3 M points).  On a cluster each piece of a :class:`PieceStore` keeps its own.
    """

    def __init__(self, raw: dict[str, np.ndarray], scale, offset, origin) -> None:
        self.raw = {k: np.asarray(raw[k]) for k in ("x", "y", "z")}
        self._bins: tuple[bytes, tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None
        n = len(self.raw["x"])
        sc, of = np.asarray(scale, float), np.asarray(offset, float)
        if n:
            lo = [float(self.raw[a].min() * sc[i] + of[i]) for i, a in enumerate("xyz")]
            hi = [float(self.raw[a].max() * sc[i] + of[i]) for i, a in enumerate("xyz")]
        else:
            lo = hi = [0.0, 0.0, 0.0]
        bounds = lo + hi
        self.meta = MemoryMeta(tuple(sc), tuple(of), tuple(float(v) for v in origin), n, bounds)
        self.tiles = [MemoryTile("memory", n, bounds)]

    def read(self, tile: Any, columns) -> dict[str, np.ndarray]:
        return {c: self.raw[c] for c in columns}

    def cached_bins(self, grid: Grid, tile: Any = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``grid.raw_bins`` of the points, computed once per grid (read-only arrays; the grid's affine map
        is the key, so another frame or bin width computes them again and replaces them)."""
        affine = grid.raw_affine(self.meta)
        key = affine.tobytes()
        if self._bins is None or self._bins[0] != key:
            bins = grid.raw_bins(self.raw, affine)
            for b in bins:
                b.flags.writeable = False
            self._bins = (key, bins)
        return self._bins[1]

    def drop_bins(self) -> None:
        """Forget the kept bins (memory)."""
        self._bins = None

    def xy_local(self) -> np.ndarray:
        """Horizontal coordinates relative to the origin (float64 ``(n, 2)``)."""
        m = self.meta
        return np.stack([self.raw[a] * m.scale[i] + (m.offset[i] - m.origin[i]) for i, a in enumerate("xy")],
                        axis=1)


class PieceStore:
    """A :class:`MemoryStore` whose tiles are pieces of its points held by the workers, one piece per worker
    thread, so that the refinement's histogram passes run as one task per piece on the cluster.

    Each piece (a contiguous slice of the points, a :class:`MemoryStore` that
    keeps its own bins) is sent once to one worker; a pass's task for a piece
    takes the piece's future as its input (:meth:`task_input`), so dask runs it
    where the piece is.  The store itself pickles to its metadata and tile
    names; the whole store (tile ``"memory"``) stays with the task that made it.
    A pass sums integer counts over tiles, so its result does not depend on how
    the points are split.
    """

    def __init__(self, mem: MemoryStore, client, slots: list[str]) -> None:
        n = mem.meta.point_count
        cuts = np.linspace(0, n, len(slots) + 1).astype(np.int64)
        m = mem.meta
        self._mem: MemoryStore | None = mem
        self._futures = []
        self.tiles = []
        for i, (a0, a1, addr) in enumerate(zip(cuts[:-1], cuts[1:], slots)):
            piece = MemoryStore({a: mem.raw[a][a0:a1] for a in "xyz"}, m.scale, m.offset, m.origin)
            self._futures.append(client.scatter(piece, workers=[addr], hash=False))
            self.tiles.append(MemoryTile(f"piece-{i}", piece.meta.point_count, piece.meta.bounds))
        self.meta = m

    def __getstate__(self) -> dict[str, Any]:
        return {"meta": self.meta, "tiles": self.tiles}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._mem, self._futures = None, []

    def task_input(self, tile: str):
        """What a pass's task gets for ``tile``: the future of its piece (dask resolves it on the worker)."""
        return self._futures[int(str(tile).rsplit("-", 1)[1])]

    def _piece(self, tile: Any) -> MemoryStore:
        if isinstance(tile, MemoryStore):
            return tile
        if tile == "memory" and self._mem is not None:
            return self._mem
        raise KeyError(f"{tile!r}: a piece is read through its task input")

    def read(self, tile: Any, columns) -> dict[str, np.ndarray]:
        return self._piece(tile).read(tile, columns)

    def cached_bins(self, grid: Grid, tile: Any = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self._piece(tile).cached_bins(grid, tile)


def in_task() -> bool:
    """Whether this code runs in a dask worker's task."""
    try:
        from distributed import get_worker

        get_worker()
    except ValueError:
        return False
    return True
