"""One part of a refined space: recursive slicing and merging of its points in one frame.

The passes are the building's (:mod:`engine.spaces.slicing`, :mod:`engine.spaces.merging`) run on a
:class:`engine.spaces.memory_store.MemoryStore`, with ridge dividers (:mod:`engine.spaces.ridges`) and
ceiling steps (:mod:`engine.spaces.ceilings`) besides the voids.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from engine.spaces.alignment import Frame
from engine.spaces.bin_counts import CountedStore
from engine.spaces.histograms import BoxIndex, Grid
from engine.spaces.memory_store import MemoryStore, PieceStore, in_task
from engine.spaces.slicing import Box, FoundDivider


@dataclass
class Part:
    """The cells of one frame of a refined space (bins of its grid), their space and their faces."""

    yaw: float
    cells: list[Box] = field(default_factory=list)
    labels: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    edges: list[Any] = field(default_factory=list)
    dividers: list[FoundDivider] = field(default_factory=list)

    @property
    def n_spaces(self) -> int:
        return int(self.labels.max()) + 1 if len(self.labels) and self.labels.max() >= 0 else 0

    def index(self, floor_bins: tuple[int, int]) -> BoxIndex:
        """Locates points in the part's cells (its storey as storey 0)."""
        rows = np.array([[0, c.u0, c.u1, c.v0, c.v1] for c in self.cells], dtype=np.int64).reshape(-1, 5)
        return BoxIndex.build(np.array([floor_bins], dtype=np.int64), rows)


def parse_part(mem: MemoryStore, yaw: float, grid: Grid, params, floor: int, floors: np.ndarray,
                band_z: np.ndarray, pieces_points: int = 0) -> Part:
    """Recursive slicing and merging of a memory store's points in the frame ``yaw``.

    In a dask task on a cluster with more than one thread, the histogram passes
    of a space of at least ``pieces_points`` points (> 0) run as tasks over
    pieces of its points (:class:`PieceStore`): the refinement of one large
    space no longer keeps the other workers idle.
    """
    if pieces_points <= 0 or mem.meta.point_count < pieces_points or not in_task():
        return _parse_part_with(mem, mem, yaw, grid, params, floor, floors, band_z, None)
    from distributed import worker_client

    with worker_client() as client:
        workers = client.scheduler_info()["workers"]
        slots = [a for a in sorted(workers) for _ in range(max(1, int(workers[a].get("nthreads", 1))))]
        if len(slots) < 2:
            return _parse_part_with(mem, mem, yaw, grid, params, floor, floors, band_z, None)
        return _parse_part_with(mem, PieceStore(mem, client, slots), yaw, grid, params, floor, floors, band_z,
                                client)


def _parse_part_with(mem: MemoryStore, passes, yaw: float, grid: Grid, params, floor: int, floors: np.ndarray,
                     band_z: np.ndarray, client) -> Part:
    """:func:`parse_part` with the histogram passes over ``passes`` (``mem`` or its :class:`PieceStore`)."""
    from engine.spaces.ceilings import ceiling_dividers, ceiling_occupancy, step_lines
    from engine.spaces.merging import merge, neighbour_edges, ridge_faces, test_edges
    from engine.spaces.ridges import Occupancy, space_ridges
    from engine.spaces.slicing import slice_storeys

    out = Part(yaw)
    if mem.meta.point_count == 0:
        return out
    sub = Grid.for_store(mem, Frame(yaw, tuple(grid.frame.origin)), grid.bin_width, grid.z_bin)
    fl = np.asarray(floors, dtype=np.int64)[floor:floor + 1]
    bz = np.asarray(band_z, dtype=np.int64)[floor:floor + 1]
    bu, bv, bzs = sub.tile_bins(mem, "memory")
    start = [Box(0, int(bu.min()), int(bu.max()) + 1, int(bv.min()), int(bv.max()) + 1)]
    # walls seen as one dense surface (no void): ridge lines over the space's upper band (engine.spaces.ridges)
    ridges = space_ridges(bu, bv, bzs, int(bz[0]), grid.z_bin, params.ridges, grid.bin_width)
    # a ceiling that changes height is a wall too (engine.spaces.ceilings): its step lines cut and divide like ridges
    ceiling = ceiling_occupancy(bu, bv, bzs, int(bz[0]), params.ceilings, grid.bin_width, grid.z_bin)
    ridges = ridges + step_lines(ceiling, params.ceilings, params.ridges, grid.bin_width, grid.z_bin, ridges,
                                 points=(bu, bv, bzs), floor_z=int(bz[0]) - int(round(params.upper_band / grid.z_bin)))
    occ = (Occupancy.build(bu, bv, bzs, int(bz[0]), params.ridges.bins(params.ridges.occupancy_pixel, grid.bin_width))
           if ridges else None)
    if passes is not mem:  # the passes read the pieces: this task's copy of the bins is no longer needed
        del bu, bv, bzs
        mem.drop_bins()
    # the passes read the points counted per (u, v, storey, band) bin (engine.spaces.bin_counts)
    passes = CountedStore(passes, sub, BoxIndex.build(fl, np.zeros((0, 5), np.int64)), bz, client,
                          [t.name for t in passes.tiles])
    cells, dividers, _ = slice_storeys(passes, sub, [tuple(fl[0])], start, params.slicing_walls, bz, client=client,
                                       max_levels=params.max_levels, ridges=ridges, ridge_params=params.ridges)
    edges = neighbour_edges(cells, params.walls.bins(params.min_face))
    test_edges(passes, sub, fl, cells, edges, params.walls, params.merge_window, bz, client=client)
    passes.release()
    # a side with a ceiling in the storey and a side without one (a stair shaft) are not one room
    edges = ceiling_dividers(edges, ceiling, params.ceilings, grid.bin_width)
    if ridges:
        edges = ridge_faces(edges, ridges, params.ridges, grid.bin_width, occ)
    comps = merge(cells, edges, grid.bin_width, params.rules)
    for c in cells:
        c.floor = floor
    for e in edges:
        e.floor = floor
    for d in dividers:
        d.floor, d.yaw = floor, (None if yaw == grid.frame.yaw else yaw)
    out.cells, out.labels, out.edges, out.dividers = cells, comps.labels, edges, dividers
    return out
