"""CRS records parsed, compared and named through pyproj, however a source wrote them."""
from __future__ import annotations

import struct

import laspy
import numpy as np
import pytest
from pyproj import CRS

from tiles.crs import geojson_crs_member, parse_crs, same_crs
from tiles.errors import UserError
from tiles.ingest import ingest

UTM33 = CRS.from_epsg(32633)


def _keys(*pairs):
    return {"geotiff": {"keys": [[k, 0, 1, v] for k, v in pairs]}}


def test_the_same_crs_as_wkt_and_as_geotiff_keys_is_one_crs():
    as_wkt = {"wkt": UTM33.to_wkt("WKT1_GDAL")}
    as_keys = _keys((1024, 1), (3072, 32633))
    assert parse_crs(as_keys) == UTM33
    assert same_crs(as_wkt, as_keys) and same_crs(as_keys, as_wkt)
    assert not same_crs(as_wkt, _keys((1024, 1), (3072, 32634)))
    # a compound CRS matches its horizontal part; a vertical key makes a compound CRS
    compound = _keys((1024, 1), (3072, 32633), (4096, 5703))
    assert parse_crs(compound).is_compound
    assert same_crs(compound, as_wkt)
    assert not same_crs(compound, {"epsg": 32634})


def test_unreadable_or_user_defined_records_give_no_crs_and_compare_as_written(monkeypatch):
    import tiles.crs

    warned = []
    monkeypatch.setattr(tiles.crs.logger, "warning", lambda msg, *a: warned.append(msg % a))
    assert parse_crs(None) is None and parse_crs({}) is None
    assert parse_crs(_keys((1024, 1), (3072, 32767))) is None  # user-defined: no EPSG code to go by
    assert not warned
    assert parse_crs({"wkt": 'PROJCS["A"]'}) is None
    assert len(warned) == 1 and "not understood" in warned[0]
    assert same_crs({"wkt": 'PROJCS["A"]'}, {"wkt": 'PROJCS["A"]'})
    assert not same_crs({"wkt": 'PROJCS["A"]'}, {"wkt": 'PROJCS["B"]'})
    assert not same_crs({"wkt": 'PROJCS["A"]'}, {"epsg": 32633})


def test_geojson_member_names_the_epsg_code_as_gdal_reads_it_else_the_wkt():
    assert geojson_crs_member(None) is None
    assert geojson_crs_member(UTM33) == {"type": "name", "properties": {"name": "urn:ogc:def:crs:EPSG::32633"}}
    local = CRS.from_proj4("+proj=tmerc +lon_0=13.3 +x_0=500000 +ellps=GRS80 +units=m")
    name = geojson_crs_member(local)["properties"]["name"]
    assert CRS.from_wkt(name).equals(local)


def _write(path, crs_vlr, n=40):
    las = laspy.LasData(laspy.LasHeader(point_format=6, version="1.4"))
    las.header.scales = np.array([0.01] * 3)
    las.header.offsets = np.array([500000.0, 5500000.0, 0.0])
    rng = np.random.default_rng(1)
    las.x, las.y, las.z = 500000 + rng.uniform(0, 9, n), 5500000 + rng.uniform(0, 9, n), rng.uniform(0, 3, n)
    las.header.vlrs.append(crs_vlr)
    las.write(str(path))


def test_ingest_takes_one_crs_said_two_ways_and_refuses_two(tmp_path):
    wkt = laspy.VLR("LASF_Projection", 2112, "OGC WKT", UTM33.to_wkt("WKT1_GDAL").encode() + b"\0")
    geokeys = laspy.VLR("LASF_Projection", 34735, "GeoKeys", struct.pack("<12H", 1, 1, 0, 2, 1024, 0, 1, 1,
                                                                          3072, 0, 1, 32633))
    other = laspy.VLR("LASF_Projection", 34735, "GeoKeys", struct.pack("<12H", 1, 1, 0, 2, 1024, 0, 1, 1,
                                                                        3072, 0, 1, 32634))
    _write(tmp_path / "a.las", wkt)
    _write(tmp_path / "b.las", geokeys)
    _write(tmp_path / "c.las", other)
    store = ingest([str(tmp_path / "a.las"), str(tmp_path / "b.las")], str(tmp_path / "ab.zarr"))
    assert parse_crs(store.meta.crs) == UTM33
    with pytest.raises(UserError, match="coordinate reference system differs"):
        ingest([str(tmp_path / "b.las"), str(tmp_path / "c.las")], str(tmp_path / "bc.zarr"))
    only_keys = ingest([str(tmp_path / "b.las")], str(tmp_path / "b.zarr"))
    assert "wkt" not in only_keys.meta.crs and parse_crs(only_keys.meta.crs) == UTM33
