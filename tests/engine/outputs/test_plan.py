"""The architect's floor plan: element footprints, door symbols, scale bar, and what is drawn per storey."""
from __future__ import annotations

import math

import numpy as np
import pytest

from engine.outputs.plan import door_swing, draw_plan, footprint, scale_length


def _box(cls, center, size, yaw=0.0, space=0):
    return {"class": cls, "center": list(center), "size": list(size), "yaw": yaw, "space_id": space, "score": 1.0}


def _room(i, x0, floor=0):
    ring = [[x0, 0], [x0 + 4, 0], [x0 + 4, 3], [x0, 3], [x0, 0]]
    return {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [ring]},
            "properties": {"id": i, "floor": floor, "area_m2": 12.0}}


def test_footprint_is_the_rotated_box_and_thin_walls_are_thickened():
    c = footprint([1.0, 2.0, 0.0], [4.0, 0.02, 3.0], math.pi / 2, min_thickness=0.1)
    # yawed by 90 degrees: the 4 m side runs along y, the 2 cm side (drawn 10 cm) along x
    assert np.allclose(c[:, 0].max() - c[:, 0].min(), 0.1) and np.allclose(c[:, 1].max() - c[:, 1].min(), 4.0)
    assert np.allclose(c.mean(axis=0), [1.0, 2.0])


def test_door_swings_into_its_space_about_a_hinge_at_one_end():
    door = _box("door", [2.0, 0.0, 1.0], [0.9, 0.08, 2.1])
    into = door_swing(door, towards=[2.0, 1.5])  # the space lies at +y
    assert into["width"] == pytest.approx(0.9)
    assert np.allclose(into["hinge"], [1.55, 0.0]) and np.allclose(into["leaf_end"], [1.55, 0.9])
    out = door_swing(door, towards=[2.0, -1.5])
    assert np.allclose(out["leaf_end"], [1.55, -0.9])
    for sw in (into, out):
        assert sw["theta"][1] - sw["theta"][0] == pytest.approx(90.0)


def test_scale_bar_is_a_round_length_near_a_fifth_of_the_plan():
    assert scale_length(18.5) == 2.0 and scale_length(60.0) == 10.0 and scale_length(3.0) == 0.5
    assert scale_length(800.0) == 100.0


def test_each_storey_draws_its_own_walls_doors_and_windows_to_png_and_svg(tmp_path):
    spaces = {"type": "FeatureCollection", "features": [_room(0, 0), _room(1, 4), _room(2, 0, floor=1)]}
    elements = [_box("wall", [4.0, 1.5, 1.5], [0.12, 3.0, 3.0], space=0),
                _box("wall", [2.0, 3.0, 1.5], [4.0, 0.1, 3.0], space=0),
                _box("door", [4.0, 1.0, 1.0], [0.08, 0.9, 2.1], space=1),
                _box("window", [6.0, 3.0, 1.5], [1.2, 0.05, 1.2], space=1),
                _box("wall", [2.0, 0.0, 4.5], [4.0, 0.1, 3.0], space=2),
                _box("chair", [1.0, 1.0, 0.4], [0.5, 0.5, 0.8], space=0),
                _box("column", [3.5, 2.5, 1.5], [0.3, 0.3, 3.0], space=0)]
    out = draw_plan(spaces, elements, tmp_path / "p.png", tmp_path / "p.svg", crs_known=True)
    assert out["storeys"][0] == {"spaces": 2, "wall": 2, "column": 1, "window": 1, "door": 1, "beam": 0}
    assert out["storeys"][1] == {"spaces": 1, "wall": 1, "column": 0, "window": 0, "door": 0, "beam": 0}
    assert (tmp_path / "p.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    import xml.etree.ElementTree as ET

    svg = (tmp_path / "p.svg").read_text()
    ET.fromstring(svg)  # well-formed
    assert "storey 1" in svg and ">N<" in svg and svg.count("12.0 m²") == 3  # labels are text in the SVG


def test_without_a_crs_there_is_no_north_arrow(tmp_path):
    spaces = {"type": "FeatureCollection", "features": [_room(0, 0)]}
    fig = draw_plan(spaces, [], crs_known=False)["figure"]
    assert not any(t.get_text() == "N" for ax in fig.axes for t in ax.texts)
    fig = draw_plan(spaces, [], crs_known=True)["figure"]
    assert any(t.get_text() == "N" for ax in fig.axes for t in ax.texts)
