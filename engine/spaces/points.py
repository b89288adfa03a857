"""A space's points, gathered from only the tiles it touches.

:func:`index_spaces` runs one task per tile that counts the points of every
space id in the tile (``space_id`` at run time, ``gt_space`` for training and for
evaluating detection alone); :func:`load_space` then reads, inside one task per
space, only the tiles that hold the space, and keeps its points.  Memory per
task is bounded by the largest space, never the building.

Colours are normalised to ``[0, 1]`` by the store's ``color_depth``; a store
that says 16 bits but holds only 8-bit values (a common LAS habit) is detected
from the data and scaled by 255 instead.
"""
from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np

from tiles.errors import UserError
from tiles.tasks import run_tasks

COLOR_COLUMNS = ("red", "green", "blue")


@dataclass
class SpaceRef:
    """Where a space lives: its id, the tiles holding its points and its point count."""

    space_id: int
    tiles: list[str] = field(default_factory=list)
    count: int = 0


@dataclass
class SpacePoints:
    """The points of one space: store-local coordinates, colours in [0, 1] (or None), optional truth."""

    space_id: int
    xyz: np.ndarray
    rgb: np.ndarray | None
    gt_class: np.ndarray | None = None
    gt_instance: np.ndarray | None = None


def _tile_space_counts(tile: str, store, space_array: str) -> dict[int, int]:
    ids = store.read(tile, [space_array])[space_array]
    u, c = np.unique(ids, return_counts=True)
    return {int(a): int(b) for a, b in zip(u, c) if a >= 0}


def index_spaces(store, space_array: str = "space_id", *, client=None, min_points: int = 1) -> list[SpaceRef]:
    """The spaces of a store (ids >= 0 of ``space_array``) with their tiles, by increasing id."""
    if store.meta.dimension(space_array) is None:
        raise UserError(store.url, f"the store has no per-point {space_array!r} array "
                                   f"({'run space parsing first' if space_array == 'space_id' else 'no ground truth'})")
    names = [t.name for t in store.tiles if t.count > 0]
    counts = run_tasks(_tile_space_counts, names, client=client, label=f"index {space_array}", keys=names,
                       extra_args=(store, space_array))
    refs: dict[int, SpaceRef] = defaultdict(lambda: SpaceRef(-1))
    for tile, cnt in zip(names, counts):
        for sid, n in cnt.items():
            r = refs[sid]
            r.space_id = sid
            r.tiles.append(tile)
            r.count += n
    return [refs[s] for s in sorted(refs) if refs[s].count >= min_points]


def color_scale(store) -> float | None:
    """The divisor that brings the store's colours to [0, 1], or None when it has no colour."""
    if not all(store.meta.dimension(c) is not None for c in COLOR_COLUMNS):
        return None
    return 255.0 if store.meta.color_depth == 8 else 65535.0


def load_space(store, ref: SpaceRef, space_array: str = "space_id", *, truth: bool = False,
               colour: bool = True) -> SpacePoints:
    """Read one space's points from the tiles it touches (inside a task); ``colour=False``: coordinates only
    (``rgb`` None), the colour columns not read."""
    has_color = colour and color_scale(store) is not None
    cols = (list(COLOR_COLUMNS) if has_color else []) + (["gt_class", "gt_instance"] if truth else [])
    xyz, rgb, gcls, ginst = [], [], [], []
    for tile in ref.tiles:
        sel = np.nonzero(store.read(tile, [space_array])[space_array] == ref.space_id)[0]
        if not len(sel):
            continue
        # a tile's points are stored in spatial order: a space's rows are a few of its chunks, and
        # only the span from its first to its last row is read and decoded
        start, stop = int(sel[0]), int(sel[-1]) + 1
        sel -= start
        data = store.read(tile, cols, start, stop) if cols else {}
        xyz.append(store.xyz(tile, start=start, stop=stop)[sel])
        if has_color:
            rgb.append(np.stack([data[c][sel] for c in COLOR_COLUMNS], axis=1))
        if truth:
            gcls.append(data["gt_class"][sel])
            ginst.append(data["gt_instance"][sel])
    pts = np.concatenate(xyz) if xyz else np.zeros((0, 3))
    colors = None
    if has_color and rgb:
        raw = np.concatenate(rgb)
        scale = color_scale(store)
        if scale == 65535.0 and len(raw) and raw.max() <= 255:
            scale = 255.0  # 8-bit values in 16-bit fields
        colors = raw.astype(np.float64) / scale
    return SpacePoints(ref.space_id, pts, colors,
                       np.concatenate(gcls) if truth and gcls else None,
                       np.concatenate(ginst) if truth and ginst else None)
