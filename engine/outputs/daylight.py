"""Natural illumination per space (paper Sec. 5): glazing, window-to-floor ratio, window orientation, daylight factor.

For each space, from its detected windows (``elements.json``) and its footprint
and height (``spaces.geojson``):

* ``glazed_area_m2``: the windows' face areas (longer horizontal side x height);
* ``window_to_floor``: glazed area over floor area;
* ``window_bearings_deg``: per window, the bearing of its outward normal (the
  side away from the space's centre), clockwise from north.  With a CRS the
  bearing is true (grid bearing plus the meridian convergence at the building,
  from pyproj); without one it is a grid bearing (from the +y axis), and
  ``bearing_reference`` says so;
* ``daylight_factor_pct``: the average daylight factor of the BRE formula
  (Littlefair, *Site layout planning for daylight and sunlight*, BRE 209,
  2011; BS 8206-2)::

      DF = T * Aw * theta / (A * (1 - R^2))     [%]

  with ``T`` the glazing's diffuse visible transmittance (``TRANSMITTANCE``,
  clean double glazing), ``Aw`` the glazed area (m²), ``theta`` the angle of
  visible sky in degrees seen from the window's centre (``SKY_ANGLE``: 90 for an
  unobstructed vertical window; we cannot see obstructions outside the scan,
  so it is the upper bound), ``A`` the area of all the room's surfaces
  (floor, ceiling and walls, windows included: 2 x floor + perimeter x height)
  and ``R`` their area-weighted mean reflectance (``REFLECTANCE``, light
  interiors).  A room with DF >= 2 % is commonly called well daylit, >= 5 %
  strongly daylit.  The constants are the formula's usual defaults, not
  measured on the scan; they are recorded with the figures.
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from engine.metrics.boxes import long_axis

TRANSMITTANCE = 0.68
SKY_ANGLE = 90.0
REFLECTANCE = 0.5


def average_daylight_factor(glazed_m2: float, floor_m2: float, perimeter_m: float, height_m: float, *,
                            transmittance: float = TRANSMITTANCE, sky_angle: float = SKY_ANGLE,
                            reflectance: float = REFLECTANCE) -> float | None:
    """The BRE average daylight factor (%) of a room; None when the room has no surface."""
    surfaces = 2.0 * floor_m2 + perimeter_m * height_m
    if surfaces <= 0:
        return None
    return transmittance * glazed_m2 * sky_angle / (surfaces * (1.0 - reflectance ** 2))


def outward_bearing(window: dict[str, Any], centre: np.ndarray, convergence_deg: float = 0.0) -> float:
    """Bearing (degrees clockwise from north, 0-360) of a window's normal pointing away from ``centre``."""
    axis, _ = long_axis(window["size"], float(window["yaw"]))
    normal = np.array([-axis[1], axis[0]])
    if float(np.dot(np.asarray(window["center"][:2], float) - centre, normal)) < 0:
        normal = -normal
    grid = math.degrees(math.atan2(normal[0], normal[1]))  # clockwise from +y
    return round((grid + convergence_deg) % 360.0, 1)


def meridian_convergence(crs_text: str | None, x: float, y: float) -> float | None:
    """Degrees to add to a grid bearing at ``(x, y)`` of the CRS to make it a true bearing; None if unknown."""
    if not crs_text:
        return None
    try:
        from pyproj import CRS, Proj, Transformer

        crs = CRS.from_user_input(crs_text)
        if not crs.is_projected:
            return None
        lon, lat = Transformer.from_crs(crs, crs.geodetic_crs, always_xy=True).transform(x, y)
        # pyproj's meridian convergence: the angle from true north to grid north, clockwise positive (checked:
        # UTM 33N at 17 E, 60 N gives +1.73 degrees, and true north lies at grid bearing -1.73 there)
        return float(Proj(crs).get_factors(lon, lat).meridian_convergence)
    except Exception:  # noqa: BLE001 - no pyproj, or a CRS it cannot place: grid bearings
        return None


def daylight(layer: dict[str, Any], elements: Iterable[dict[str, Any]], crs_text: str | None = None
             ) -> dict[int, dict[str, Any]]:
    """Per space id: glazed area, window-to-floor ratio, window bearings and the average daylight factor."""
    from shapely.geometry import shape

    feats = {int(f["properties"]["id"]): f for f in layer.get("features", [])}
    windows: dict[int, list[dict[str, Any]]] = {i: [] for i in feats}
    for e in elements:
        if e.get("class") == "window" and int(e.get("space_id", -1)) in windows:
            windows[int(e["space_id"])].append(e)
    geoms = {i: shape(f["geometry"]) for i, f in feats.items() if (f.get("geometry") or {}).get("coordinates")}
    gamma = None
    if geoms:
        c = np.mean([np.asarray(g.centroid.coords[0]) for g in geoms.values()], axis=0)
        gamma = meridian_convergence(crs_text, float(c[0]), float(c[1]))
    out = {}
    for i, f in feats.items():
        p, g = f["properties"], geoms.get(i)
        floor = float(g.area) if g is not None else 0.0
        perimeter = float(g.length) if g is not None else 0.0
        height = float(p.get("z_max", 0.0)) - float(p.get("z_min", 0.0))
        glazed = float(sum(max(w["size"][0], w["size"][1]) * w["size"][2] for w in windows[i]))
        centre = np.asarray(g.centroid.coords[0]) if g is not None else np.zeros(2)
        df = average_daylight_factor(glazed, floor, perimeter, height)
        out[i] = {"glazed_area_m2": round(glazed, 3),
                  "window_to_floor": round(glazed / floor, 4) if floor > 0 else None,
                  "window_bearings_deg": [outward_bearing(w, centre, gamma or 0.0) for w in windows[i]],
                  "bearing_reference": "true north" if gamma is not None else "grid north (+y; no CRS)",
                  "daylight_factor_pct": None if df is None else round(df, 2)}
    return out


def add_daylight_to_geojson(layer: dict[str, Any], figures: dict[int, dict[str, Any]]) -> dict[str, Any]:
    """A copy of the layer with the daylight figures in each feature's properties."""
    feats = []
    for f in layer.get("features", []):
        extra = figures.get(int(f["properties"]["id"]), {})
        feats.append(dict(f, properties={**f["properties"], **extra}))
    return dict(layer, features=feats)


def layer_with_figures(layer: dict[str, Any], elements: list[dict[str, Any]], crs_text: str | None = None
                       ) -> tuple[dict[str, Any], dict[str, Any]]:
    """The spaces layer with each space's statistics and daylight figures in its properties, and the statistics
    (:func:`engine.outputs.statistics.space_statistics`, each space's row with its daylight figures too)."""
    from engine.outputs.statistics import add_statistics_to_geojson, space_statistics

    stats = space_statistics(layer, elements)
    figures = daylight(layer, elements, crs_text)
    for row in stats["spaces"]:
        row.update(figures.get(int(row["id"]), {}))
    return add_daylight_to_geojson(add_statistics_to_geojson(layer, stats), figures), stats
