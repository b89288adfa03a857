"""The labels of space parsing in the tiles: ``cell_id`` and ``space_id`` of every point (one task per tile).

A refined space's points are located in its refinement's cells (:func:`relabel`).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from engine.spaces.histograms import BoxIndex, Grid
from engine.spaces.refine import Refinement


def label_tile(tile: str, store, grid: Grid, index: BoxIndex, cell_space: np.ndarray,
                refined: list[tuple[Refinement, list[tuple[Grid, BoxIndex, int]]]], owner: np.ndarray
                ) -> dict[str, Any]:
    """Write ``cell_id`` and ``space_id`` of one tile; its cells' and spaces' point counts and z ranges (sparse).

    Points of a refined space are located in its refinement's cells (:func:`relabel`).
    """
    m = store.meta
    raw = store.read(tile, ("x", "y", "z"))
    bu, bv, bz = grid.raw_bins(raw, grid.raw_affine(m))
    cell = index.locate(bu, bv, bz)
    if refined:
        cell = relabel(cell, raw, m, refined, owner)
    space = np.append(cell_space, -1)[cell]  # cell -1 -> space -1
    store.write_array(tile, "cell_id", cell.astype(np.int32))
    store.write_array(tile, "space_id", space.astype(np.int32))
    inside = cell >= 0
    per = np.bincount(cell[inside], minlength=len(cell_space))
    cells = np.flatnonzero(per)
    counts = per[cells]
    # z range per cell from the raw integers (monotonic in z); the driver reduces them per space
    big = np.iinfo(np.int64).max
    zmin_all, zmax_all = np.full(len(cell_space), big), np.full(len(cell_space), -big)
    zr = raw["z"][inside].astype(np.int64)
    np.minimum.at(zmin_all, cell[inside], zr)
    np.maximum.at(zmax_all, cell[inside], zr)
    zmin, zmax = zmin_all[cells], zmax_all[cells]
    return {"cells": cells, "counts": counts, "zmin": zmin * m.scale[2] + m.offset[2],
            "zmax": zmax * m.scale[2] + m.offset[2], "unassigned": int((space < 0).sum())}


def relabel(cell: np.ndarray, raw: dict[str, np.ndarray], meta, refined: list[tuple[Refinement, list]],
            owner: np.ndarray) -> np.ndarray:
    """New cell ids of a tile's points: points of a refined space are located in its refinement's cells.

    ``owner[cell + 1]`` is the refinement index of a building cell (-1: not refined);
    ``refined[k]`` = (refinement, [(grid, index, first new cell id) per part]).  Points of a
    refined space outside every one of its new cells get -1.
    """
    out = cell.copy()
    who = owner[cell + 1]
    for k in np.unique(who[who >= 0]).tolist():
        ref, parts = refined[k]
        sel = np.flatnonzero(who == k)
        part = {a: raw[a][sel] for a in "xyz"}
        if ref.regions is not None:
            xy = np.stack([part[a] * meta.scale[i] + (meta.offset[i] - meta.origin[i]) for i, a in enumerate("xy")],
                          axis=1)
            which = ref.part_of(xy)
        else:
            which = np.zeros(len(sel), dtype=np.int64)
        new = np.full(len(sel), -1, dtype=np.int64)
        for j, (g, idx, first) in enumerate(parts):
            mine = np.flatnonzero(which == j)
            if not len(mine):
                continue
            sub = idx.locate(*g.raw_bins({a: part[a][mine] for a in "xyz"}, g.raw_affine(meta)))
            new[mine] = np.where(sub >= 0, sub + first, -1)
        out[sel] = new
    return out
