"""Spaces as GeoJSON and GeoPackage, read back by GDAL (pyogrio) at the right place, in the right CRS."""
from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pyogrio
import shapely
from pyogrio.raw import read
from pyproj import CRS
from shapely.geometry import shape

from engine.outputs.geojson import oriented, spaces_feature_collection, write_spaces_geojson, write_spaces_gpkg

X0, Y0 = 500012.0, 5500000.0  # a building in UTM 33N: GDAL without the CRS would put it at "longitude 500012"


def _space(sid, footprint, floor=0):
    return SimpleNamespace(id=sid, footprint=footprint, area_m2=shape(footprint).area, floor=floor,
                           z_range=(0.0, 3.0), point_count=100 + sid)


def _parse():
    cw = [[X0, Y0], [X0, Y0 + 4], [X0 + 5, Y0 + 4], [X0 + 5, Y0], [X0, Y0]]  # clockwise
    hole_ccw = [[X0 + 6, Y0 + 1], [X0 + 7, Y0 + 1], [X0 + 7, Y0 + 2], [X0 + 6, Y0 + 2], [X0 + 6, Y0 + 1]]
    outer = [[X0 + 5, Y0], [X0 + 5, Y0 + 4], [X0 + 9, Y0 + 4], [X0 + 9, Y0], [X0 + 5, Y0]]
    far = [[X0 + 20, Y0], [X0 + 20, Y0 + 2], [X0 + 22, Y0 + 2], [X0 + 22, Y0], [X0 + 20, Y0]]
    return SimpleNamespace(spaces=[_space(0, {"type": "Polygon", "coordinates": [cw]}),
                                   _space(1, {"type": "MultiPolygon", "coordinates": [[outer, hole_ccw], [far]]})])


def _rings(geom):
    g = shape(geom)
    polys = list(g.geoms) if g.geom_type == "MultiPolygon" else [g]
    return polys


def test_exterior_rings_run_counter_clockwise_and_holes_clockwise():
    for s in _parse().spaces:
        for p in _rings(oriented(s.footprint)):
            assert p.exterior.is_ccw and all(not r.is_ccw for r in p.interiors)
            assert p.area > 0
    point = {"type": "Point", "coordinates": [1.0, 2.0]}
    assert oriented(point) == point


def test_geojson_and_gpkg_read_back_by_gdal_in_place_and_crs(tmp_path):
    crs = CRS.from_epsg(32633)
    parse = _parse()
    path = write_spaces_geojson(parse, tmp_path / "spaces.geojson", crs)
    doc = json.loads(open(path).read())
    assert doc["crs"] == {"type": "name", "properties": {"name": "urn:ogc:def:crs:EPSG::32633"}}
    assert CRS.from_wkt(doc["crs_wkt"]) == crs
    fc = spaces_feature_collection(parse, crs)
    fc["features"][0]["properties"]["window_to_wall"] = None  # a null, as the statistics give
    fc["features"][1]["properties"]["window_to_wall"] = 0.25
    write_spaces_gpkg(fc, tmp_path / "spaces.gpkg", crs)
    for name in ("spaces.geojson", "spaces.gpkg"):
        meta, _, wkb, fields = read(str(tmp_path / name))
        assert CRS.from_user_input(meta["crs"]) == crs, name
        got = shapely.from_wkb(wkb)
        for g, s in zip(got, parse.spaces):
            want = shape(s.footprint)
            assert g.equals(want) and g.bounds == want.bounds, name  # same place, world metres
            assert {tuple(c) for c in shapely.get_coordinates(g)} == {tuple(c) for c in shapely.get_coordinates(want)}
            for p in _rings(shapely.geometry.mapping(g)):
                assert p.exterior.is_ccw, name
        cols = dict(zip(meta["fields"], fields))
        np.testing.assert_array_equal(cols["id"], [0, 1])
        np.testing.assert_array_equal(cols["point_count"], [100, 101])
    _, _, _, fields = read(str(tmp_path / "spaces.gpkg"), columns=["window_to_wall"])
    assert np.isnan(fields[0][0]) and fields[0][1] == 0.25
    assert pyogrio.read_info(str(tmp_path / "spaces.gpkg"))["layer_name"] == "spaces"


def test_without_a_crs_no_member_and_a_crs_without_epsg_code_goes_as_wkt(tmp_path):
    parse = _parse()
    assert "crs" not in spaces_feature_collection(parse) and "crs_wkt" not in spaces_feature_collection(parse)
    local = CRS.from_proj4("+proj=tmerc +lon_0=13.3 +x_0=500000 +ellps=GRS80 +units=m")
    write_spaces_geojson(parse, tmp_path / "s.geojson", local)
    write_spaces_gpkg(spaces_feature_collection(parse, local), tmp_path / "s.gpkg", local)
    for name in ("s.geojson", "s.gpkg"):
        assert CRS.from_user_input(pyogrio.read_info(str(tmp_path / name))["crs"]).equals(local), name
    write_spaces_gpkg(spaces_feature_collection(parse), tmp_path / "none.gpkg")
    assert pyogrio.read_info(str(tmp_path / "none.gpkg"))["crs"] is None
