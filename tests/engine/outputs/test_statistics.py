"""Space statistics (paper 5.3, "emerging applications"): area, perimeter, counts, window-to-wall ratio."""
from __future__ import annotations

import copy

import pytest

from engine.outputs.statistics import add_statistics_to_geojson, face_area, space_statistics


def _square(x0, y0, x1, y1):
    return {"type": "Polygon", "coordinates": [[[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]]}


def _collection():
    holed = {"type": "Polygon", "coordinates": [[[10, 0], [20, 0], [20, 10], [10, 10], [10, 0]],
                                                [[14, 4], [16, 4], [16, 6], [14, 6], [14, 4]]]}
    return {"type": "FeatureCollection", "features": [
        {"type": "Feature", "id": 0, "geometry": _square(0, 0, 4, 5),
         "properties": {"id": 0, "area_m2": 20.0, "floor": 0, "z_min": 0.0, "z_max": 3.0, "point_count": 1234}},
        {"type": "Feature", "id": 7, "geometry": holed,
         "properties": {"id": 7, "area_m2": 96.0, "floor": 0, "z_min": 0.0, "z_max": 2.5, "point_count": 99}}]}


def _el(cls, space, size):
    return {"class": cls, "space_id": space, "center": [0, 0, 0], "size": size, "yaw": 0.0}


ELEMENTS = [_el("wall", 0, [4, 0.2, 3]), _el("wall", 0, [0.2, 5, 3]), _el("window", 0, [1.2, 0.1, 1.5]),
            _el("window", 0, [0.1, 0.8, 1.0]), _el("chair", 0, [0.5, 0.5, 0.9]), _el("chair", 7, [0.5, 0.5, 0.9]),
            _el("table", 7, [1.6, 0.8, 0.75]), _el("door", 3, [1, 0.1, 2.1]),  # space 3 is not a space
            {"class": "clutter", "space_id": 0, "size": [1, 1, 1]}]


def test_statistics_of_two_spaces():
    stats = space_statistics(_collection(), ELEMENTS)
    a, b = stats["spaces"]
    assert (a["id"], b["id"]) == (0, 7)
    assert a["area_m2"] == pytest.approx(20.0) and a["perimeter_m"] == pytest.approx(18.0)
    assert b["area_m2"] == pytest.approx(96.0) and b["perimeter_m"] == pytest.approx(40.0 + 8.0)  # hole's edge too
    assert a["height_m"] == pytest.approx(3.0) and a["points"] == 1234
    assert a["elements"]["wall"] == 2 and a["elements"]["window"] == 2 and a["elements"]["chair"] == 1
    assert b["elements"]["chair"] == 1 and b["elements"]["table"] == 1 and b["elements"]["wall"] == 0
    assert a["wall_area_m2"] == pytest.approx(12 + 15)
    assert a["window_area_m2"] == pytest.approx(1.8 + 0.8)
    assert a["window_to_wall"] == pytest.approx(2.6 / 27)
    assert b["window_to_wall"] is None  # no wall detected: no ratio, not zero
    t = stats["total"]
    assert t["spaces"] == 2 and t["area_m2"] == pytest.approx(116.0) and t["points"] == 1333
    assert t["elements"]["chair"] == 2 and t["elements"]["door"] == 0 and t["elements_outside_spaces"] == 1
    assert t["window_to_wall"] == pytest.approx(2.6 / 27)
    assert face_area([0.2, 5, 3]) == 15.0


def test_same_statistics_from_space_dicts():
    fc = _collection()
    dicts = [{"id": f["id"], "footprint": f["geometry"], "z_range": [f["properties"]["z_min"], f["properties"]["z_max"]],
              "point_count": f["properties"]["point_count"]} for f in fc["features"]]
    assert space_statistics(dicts, ELEMENTS) == space_statistics(fc, ELEMENTS)


def test_statistics_go_into_the_geojson_properties():
    fc = _collection()
    before = copy.deepcopy(fc)
    out = add_statistics_to_geojson(fc, space_statistics(fc, ELEMENTS))
    assert fc == before  # a copy, the input is left alone
    p = out["features"][0]["properties"]
    assert p["n_wall"] == 2 and p["n_window"] == 2 and p["n_sofa"] == 0
    assert p["window_to_wall"] == pytest.approx(2.6 / 27, abs=1e-4) and p["perimeter_m"] == 18.0
    assert p["point_count"] == 1234  # existing properties kept
    assert out["features"][1]["properties"]["window_to_wall"] is None
    with pytest.raises(ValueError):
        add_statistics_to_geojson({"type": "Feature"}, {})
