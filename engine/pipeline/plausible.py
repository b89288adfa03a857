"""Refuse up front, in one line, a cloud the parse cannot represent or that cannot be a building interior.

Checked on the store's metadata right after ingest, before any task of the
parse (spaces, detection) starts:

* every coordinate is finite and the extent is not zero along any axis: the
  spaces stage needs a floor and a ceiling (a z extent) and a floor plan (an
  x and a y extent);
* the points are dense enough to show a wall in the spaces stage's occupancy
  raster (``buildingparser.spaces.ridges.occupancy-pixel``, 0.1 m): on average
  at least one point per raster pixel over the occupied tiles' footprint.  A
  building interior holds its floor and its ceiling at every pixel, so a
  real scan has many times that; a cloud below it (a few points spread over
  kilometres, a sparse random cloud) would only make the parse work over
  empty space.  The footprint is counted in whole occupied tiles, so the cost
  of the check, like the parse's, follows the occupied tiles and not the
  bounding box.
"""
from __future__ import annotations

import math

from tiles.config import setting
from tiles.errors import UserError
from tiles.store import TileStore


def check_parsable(store: TileStore, source: str) -> None:
    """Raise a one-line :class:`UserError` about ``source`` when its store cannot be parsed into spaces."""
    m = store.meta
    b = [float(v) for v in m.bounds]
    if not all(math.isfinite(v) for v in b):
        raise UserError(source, f"non-finite coordinate bounds {b}")
    extent = [b[3] - b[0], b[4] - b[1], b[5] - b[2]]
    if extent[2] <= 0:
        raise UserError(source, f"all {m.point_count:,} points lie at one height z = {b[2]:g} m: "
                                "no floor and ceiling to parse")
    if extent[0] <= 0 or extent[1] <= 0:
        axis = "x" if extent[0] <= 0 else "y"
        raise UserError(source, f"all {m.point_count:,} points lie in one vertical plane ({axis} extent 0): "
                                "no floor plan to parse")
    pixel = float(setting("spaces.ridges.occupancy-pixel"))
    footprint = len(m.tiles) * float(m.tile_size) ** 2
    density = m.point_count / footprint if footprint > 0 else math.inf
    if density * pixel * pixel < 1.0:
        raise UserError(source, f"too sparse to be a building interior: {m.point_count:,} points over "
                                f"{extent[0]:,.1f} x {extent[1]:,.1f} x {extent[2]:,.1f} m, {density:.3g} points "
                                f"per m2 of the {len(m.tiles):,} occupied {m.tile_size:g} m tiles; a wall needs at "
                                f"least {1 / pixel ** 2:g} per m2 (one per {pixel:g} m occupancy pixel)")
