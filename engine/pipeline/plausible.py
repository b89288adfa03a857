"""Refuse up front, in one line, a cloud the parse cannot represent or that cannot be a building interior.

Checked by ingest on what its tasks read, before it writes the tiles, and on
the metadata of a store given as input, before any task of the parse starts:

* every coordinate is finite and the extent is not zero along any axis: the
  spaces stage needs a floor and a ceiling (a z extent) and a floor plan (an
  x and a y extent);
* the points are dense enough to be a scanned interior: on average at least
  one point per ``SPARSE_PIXELS`` x ``SPARSE_PIXELS`` pixels of the spaces
  stage's occupancy raster (``buildingparser.spaces.ridges.occupancy-pixel``,
  0.1 m: 11 points per m²) over the occupied tiles' footprint.  A building
  interior holds its floor and its ceiling under every pixel, so a real scan
  has far more; the margin of 3 x 3 pixels is there because the footprint is
  counted in whole 10 m tiles, which a building fills only in part at its edges
  (a generated 2-storey test building at low density, 300 points per m² of
  floor, gives 71 per m² of its tiles).  A cloud below it (a few points spread
  over kilometres, a sparse random cloud) would only make the parse work over
  empty space.  Counting whole occupied tiles keeps the cost of the check, like
  the parse's, with the occupied tiles and not the bounding box.
"""
from __future__ import annotations

import math

from tiles.config import setting
from tiles.errors import UserError
from tiles.ingest import CloudFacts
from tiles.store import TileStore

#: The sparsest cloud accepted has one point per this many occupancy pixels along each axis (see the module doc).
SPARSE_PIXELS = 3


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
    cell = SPARSE_PIXELS * float(setting("spaces.ridges.occupancy-pixel"))
    footprint = facts.tiles * facts.tile_size ** 2
    density = n / footprint if footprint > 0 else math.inf
    if density * cell * cell < 1.0:
        raise UserError(source, f"too sparse to be a building interior: {n:,} points over "
                                f"{extent[0]:,.1f} x {extent[1]:,.1f} x {extent[2]:,.1f} m, {density:.3g} points "
                                f"per m2 of the {facts.tiles:,} occupied {facts.tile_size:g} m tiles; an interior "
                                f"needs at least {1 / cell ** 2:.3g} per m2 (one per {cell:g} m cell)")
