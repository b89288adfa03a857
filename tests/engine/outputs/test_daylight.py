"""Natural illumination: the BRE average daylight factor of a hand-made room, window bearings, true north."""
from __future__ import annotations

import pytest

from engine.outputs.daylight import add_daylight_to_geojson, average_daylight_factor, daylight


def _room(x0=0.0, y0=0.0, crs=None):
    ring = [[x0, y0], [x0 + 6, y0], [x0 + 6, y0 + 4], [x0, y0 + 4], [x0, y0]]
    layer = {"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {
        "id": 0, "z_min": 0.0, "z_max": 3.0}, "geometry": {"type": "Polygon", "coordinates": [ring]}}]}
    if crs:
        layer["crs_wkt"] = crs
    return layer


def _window(x, y, along_x, x0=0.0, y0=0.0):
    size = [1.5, 0.1, 1.2] if along_x else [0.1, 1.5, 1.2]
    return {"class": "window", "space_id": 0, "center": [x0 + x, y0 + y, 1.5], "size": size, "yaw": 0.0}


def test_daylight_factor_of_a_hand_made_room_matches_the_hand_calculation():
    # a 6 x 4 m room, 3 m high, two 1.5 x 1.2 m windows: Aw = 3.6 m2
    # A = 2 * 24 + 20 * 3 = 108 m2; DF = 0.68 * 3.6 * 90 / (108 * (1 - 0.25)) = 220.32 / 81 = 2.72 %
    figs = daylight(_room(), [_window(3.0, 4.0, True), _window(6.0, 2.0, False)])[0]
    assert figs["glazed_area_m2"] == pytest.approx(3.6)
    assert figs["window_to_floor"] == pytest.approx(3.6 / 24, abs=1e-4)
    assert figs["daylight_factor_pct"] == pytest.approx(2.72, abs=0.005)
    assert average_daylight_factor(3.6, 24.0, 20.0, 3.0) == pytest.approx(220.32 / 81)
    # the window on the +y wall faces grid north, the one on the +x wall faces east
    assert figs["window_bearings_deg"] == [0.0, 90.0]
    assert figs["bearing_reference"].startswith("grid")


def test_with_a_crs_bearings_are_true_bearings():
    pytest.importorskip("pyproj")
    from pyproj import CRS, Transformer

    crs = CRS.from_epsg(32633)
    x0, y0 = Transformer.from_crs(4326, crs, always_xy=True).transform(17.0, 60.0)  # 2 degrees east of 15 E
    figs = daylight(_room(x0, y0, crs.to_wkt()), [_window(3.0, 4.0, True, x0, y0)], crs.to_wkt())[0]
    # grid north lies about 2 * sin(60 deg) = 1.73 degrees east of true north there
    assert figs["window_bearings_deg"][0] == pytest.approx(1.7, abs=0.05)
    assert figs["bearing_reference"] == "true north"


def test_figures_go_into_the_spaces_layer():
    layer = add_daylight_to_geojson(_room(), daylight(_room(), [_window(3.0, 0.0, True)]))
    p = layer["features"][0]["properties"]
    assert p["window_bearings_deg"] == [180.0] and p["daylight_factor_pct"] > 0 and p["z_max"] == 3.0
