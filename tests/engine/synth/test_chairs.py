"""The ``furniture`` style family: chairs of shapes the classic catalogue does not have (engine/synth/chairs.py)."""
from __future__ import annotations

from collections import Counter

import numpy as np

from engine.synth import plan_building
from engine.synth.chairs import SHAPES, chair_stream, family_chair
from engine.synth.placer import Placer


def _footprint(parts) -> np.ndarray:
    """The plan extent (x, y) of a chair's parts, turned parts included."""
    corners = []
    for cx, cy, _cz, sx, sy, _sz, _rgb, *turn in parts:
        a = sum(turn)
        for u in (-0.5, 0.5):
            for v in (-0.5, 0.5):
                corners.append([cx + np.cos(a) * u * sx - np.sin(a) * v * sy, cy + np.sin(a) * u * sx + np.cos(a) * v * sy])
    c = np.array(corners)
    return c.max(axis=0) - c.min(axis=0)


def test_each_shape_is_drawn_and_the_star_base_is_wider_than_the_classic_cross():
    drawn = [family_chair(chair_stream(7, 1, k), (0.5, 0.5, 0.5)) for k in range(200)]
    assert set(Counter(shape for _, shape in drawn)) == set(SHAPES)
    for parts, shape in drawn:
        size = _footprint(parts)
        if shape == "five-star":
            assert size.max() >= 0.54 and any(len(p) == 8 for p in parts)  # arms turned about z
        if shape == "armchair":
            assert size[0] >= 0.65
    # the same stream, the same chair
    assert family_chair(chair_stream(7, 1, 3), (0, 0, 0))[0] == family_chair(chair_stream(7, 1, 3), (0, 0, 0))[0]


def test_a_turned_part_is_a_box_turned_about_z():
    class _Space:
        z0 = 0.0

    p = Placer.__new__(Placer)
    p.space = _Space()
    (box,) = p.build([(0.2, 0.0, 0.5, 0.4, 0.05, 0.05, (1, 1, 1), np.pi / 2)], (1.0, 1.0), 0.0)
    assert np.isclose(box.yaw, np.pi / 2) and np.allclose(box.center, [1.2, 1.0, 0.5])


def test_a_furniture_building_keeps_its_plan_names_its_chairs_and_every_box_holds_its_points(helpers):
    from engine.synth import scan_building

    classic, styled = (plan_building(31, area_m2=300, density=100, styles=s) for s in ("classic", "furniture"))
    assert styled.params["styles"] == "furniture"
    assert [s.footprint.tolist() for s in styled.spaces] == [s.footprint.tolist() for s in classic.spaces]
    chairs = [e for s in styled.spaces for e in s.elements if e.cls == "chair"]
    assert len(chairs) >= 10 and len({e.info["shape"] for e in chairs}) >= 3
    assert all("shape" not in e.info for s in classic.spaces for e in s.elements if e.cls == "chair")
    scan = scan_building(styled)
    P = helpers.xyz(scan)
    doc = styled.ground_truth()["elements"]
    assert {e["shape"] for e in doc if e["class"] == "chair"} == {e.info["shape"] for e in chairs}
    for e in doc:
        sel = scan["gt_instance"] == e["id"]
        assert helpers.in_box(P[sel], e, grow=1e-6).all(), e["class"]
