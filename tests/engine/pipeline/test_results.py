"""The run's small outputs: spaces.geojson and spaces.gpkg in the input's CRS, however the input gave it."""
from __future__ import annotations

import json
from types import SimpleNamespace

import pyogrio
from pyproj import CRS
from shapely.geometry import shape

from engine.pipeline.results import write_plan_outputs

X0, Y0 = 500012.0, 5500000.0


def _final():
    ring = [[X0, Y0], [X0, Y0 + 4], [X0 + 5, Y0 + 4], [X0 + 5, Y0], [X0, Y0]]  # clockwise
    s = SimpleNamespace(id=0, footprint={"type": "Polygon", "coordinates": [ring]}, area_m2=20.0, floor=0,
                        z_range=(0.0, 3.0), point_count=10)
    return SimpleNamespace(spaces=[s])


def test_an_input_with_geotiff_keys_only_gives_both_files_its_crs(tmp_path):
    import dask

    store = SimpleNamespace(meta=SimpleNamespace(crs={"geotiff": {"keys": [[1024, 0, 1, 1], [3072, 0, 1, 32633]]},
                                                      "epsg": 32633}))
    with dask.config.set({"buildingparser.outputs.viewer": False}):  # the 3D view samples a store's tiles
        write_plan_outputs(store, _final(), [], str(tmp_path), None)
    doc = json.loads((tmp_path / "spaces.geojson").read_text())
    assert doc["crs"]["properties"]["name"] == "urn:ogc:def:crs:EPSG::32633"
    assert shape(doc["features"][0]["geometry"]).exterior.is_ccw
    assert "perimeter_m" in doc["features"][0]["properties"]  # the statistics are in both files
    for name in ("spaces.geojson", "spaces.gpkg"):
        info = pyogrio.read_info(str(tmp_path / name))
        assert CRS.from_user_input(info["crs"]) == CRS.from_epsg(32633), name
        assert list(info["total_bounds"]) == [X0, Y0, X0 + 5, Y0 + 4], name
        assert "perimeter_m" in list(info["fields"]), name
    ifc = (tmp_path / "building.ifc").read_text()
    assert "IFCPROJECTEDCRS('EPSG:32633'" in ifc  # and the building model's map conversion
