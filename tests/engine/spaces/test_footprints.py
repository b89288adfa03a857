"""Footprints are polygons: a space clipped where its cells only touch the clip keeps its area, not a line."""
from __future__ import annotations

import math

from shapely.geometry import GeometryCollection, Point, Polygon, shape

from engine.spaces.alignment import Frame
from engine.spaces.footprints import clipped_footprint, polygonal, union_footprint


def test_a_clipped_footprint_whose_cell_touches_the_clip_along_an_edge_is_a_polygon():
    frame = Frame(math.radians(30.0), (100.0, 200.0, 0.0))
    # the second cell meets the clip only along its edge x = 2: the intersection holds that line beside the square
    geojson, area = clipped_footprint([[0, 0, 2, 2], [2, 2, 3, 3]], frame, [[0, 0, 2, 3]], frame)
    assert geojson["type"] == "Polygon"
    assert area == shape(geojson).area
    assert abs(area - 4.0) < 1e-3


def test_polygonal_keeps_the_polygons_of_a_collection():
    square = Polygon([(0, 0), (1, 0), (1, 1), (0, 1)])
    far = Polygon([(5, 5), (6, 5), (6, 6), (5, 6)])
    assert polygonal(GeometryCollection([square, Point(3, 3)])).equals(square)
    two = polygonal(GeometryCollection([square, Point(3, 3), far]))
    assert two.geom_type == "MultiPolygon" and two.area == 2.0
    assert polygonal(GeometryCollection([Point(0, 0)])).is_empty
    geojson, area = union_footprint([[0, 0, 1, 1], [1, 0, 2, 1]], Frame(0.0, (0.0, 0.0, 0.0)))
    assert geojson["type"] == "Polygon" and area == 2.0
