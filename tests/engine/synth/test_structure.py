"""Structure of a space: columns floor to ceiling, beams above the doors, floor, ceiling and lights."""
from __future__ import annotations


def test_columns_reach_the_ceiling_and_beams_clear_the_doors(building):
    kinds = set()
    for s in building.spaces:
        for e in s.elements:
            if e.cls == "column":
                b = e.prims[0]
                assert b.size[2] == s.z1 - s.z0  # floor to ceiling
                kinds.add("engaged" if e.info.get("engaged") else "free")
            if e.cls == "beam":
                b = e.prims[0]
                assert b.center[2] + b.size[2] / 2 == s.z1  # under the ceiling, above the doors
                assert b.center[2] - b.size[2] / 2 > max([building.openings[i].z1 for i in s.doors] + [s.z0 + 2.0])
    assert kinds == {"engaged", "free"}


def test_every_space_has_a_floor_and_a_ceiling_and_lights_under_it(building):
    for s in building.spaces:
        classes = [e.cls for e in s.elements]
        assert classes.count("floor") == 1 and classes.count("ceiling") == 1
        for e in s.elements:
            if e.info.get("kind") == "light":
                b = e.prims[0]
                assert abs(b.center[2] + b.size[2] / 2 - s.z1) < 1e-9
