"""Refuse up front, in one line, a cloud the parse cannot represent or that cannot be a building interior.

Checked by ingest on what its tasks read, before it writes the tiles, and on
the metadata of a store given as input, before any task of the parse starts:

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
from tiles.ingest import CloudFacts
from tiles.store import TileStore


def check_parsable(store: TileStore, source: str) -> None:
    """Raise a one-line :class:`UserError` about ``source`` when its store cannot be parsed into spaces."""
    m = store.meta
    b = [float(v) for v in m.bounds]
    if not all(math.isfinite(v) for v in b):
        raise UserError(source, f"non-finite coordinate bounds {b}")
    check_cloud(CloudFacts(m.point_count, len(m.tiles), float(m.tile_size), (b[3] - b[0], b[4] - b[1], b[5] - b[2])),
                source)


def check_cloud(facts: CloudFacts, source: str) -> None:
    """The checks of the module on what ingest found (called by ingest before it writes the tiles)."""
    n, extent = facts.points, facts.extent
    if extent[2] <= 0:
        raise UserError(source, f"all {n:,} points lie at one height: no floor and ceiling to parse")
    if extent[0] <= 0 or extent[1] <= 0:
        axis = "x" if extent[0] <= 0 else "y"
        raise UserError(source, f"all {n:,} points lie in one vertical plane ({axis} extent 0): "
                                "no floor plan to parse")
    pixel = float(setting("spaces.ridges.occupancy-pixel"))
    footprint = facts.tiles * facts.tile_size ** 2
    density = n / footprint if footprint > 0 else math.inf
    if density * pixel * pixel < 1.0:
        raise UserError(source, f"too sparse to be a building interior: {n:,} points over "
                                f"{extent[0]:,.1f} x {extent[1]:,.1f} x {extent[2]:,.1f} m, {density:.3g} points "
                                f"per m2 of the {facts.tiles:,} occupied {facts.tile_size:g} m tiles; a wall needs at "
                                f"least {1 / pixel ** 2:g} per m2 (one per {pixel:g} m occupancy pixel)")
