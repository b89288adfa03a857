"""Hardness: how difficulties are named and switched, and that each one changes only what it is about."""
from __future__ import annotations

import math

import numpy as np
import pytest

from engine.synth import plan_building, scan_building
from engine.synth.hard.hardness import NAMES, Hardness
from tiles.errors import UserError


def test_parse_accepts_all_forms():
    assert not Hardness.parse(None) and not Hardness.parse("none") and not Hardness.parse("")
    assert Hardness.parse("all").to_dict() == {n: 1.0 for n in NAMES}
    assert Hardness.parse("glass,wing").to_dict() == {"glass": 1.0, "wing": 1.0}
    assert Hardness.parse(["glass", "hidden-walls"]).to_dict() == {"glass": 1.0, "hidden_walls": 1.0}
    assert Hardness.parse("glass=0.5,registration").to_dict() == {"glass": 0.5, "registration": 1.0}
    assert Hardness.parse({"walls": 2}).to_dict() == {"walls": 2.0}
    h = Hardness(glass=0.3)
    assert Hardness.parse(h) is h and h.on("glass") and not h.on("wing") and not h.geometric
    assert Hardness.parse("stairs").geometric


@pytest.mark.parametrize("spec, message", [("glas", "unknown difficulty"), ("glass=x", "must be a number"),
                                           ({"glass": 3}, "between 0 and 2"), ({"glass": -1}, "between 0 and 2")])
def test_mistakes_are_one_line_user_errors(spec, message):
    with pytest.raises(UserError, match=message):
        Hardness.parse(spec)
    with pytest.raises(UserError, match=message):
        plan_building(1, rooms=4, hardness=spec)


def test_no_difficulty_is_the_clean_building():
    clean = scan_building(plan_building(3, rooms=5, density=60))
    none = scan_building(plan_building(3, rooms=5, density=60, hardness="none"))
    for k in clean:
        np.testing.assert_array_equal(clean[k], none[k])
    assert "hardness" not in plan_building(3, rooms=5, density=60).ground_truth()["building"]


def test_a_scan_difficulty_leaves_the_plan_alone():
    """Registration and artefacts only change the scan: same spaces, walls and elements as the clean plan."""
    clean = plan_building(4, area_m2=300, density=60)
    hard = plan_building(4, area_m2=300, density=60, hardness="registration,artefacts")
    assert [w.p0 + w.p1 + (w.thickness,) for w in hard.walls] == [w.p0 + w.p1 + (w.thickness,) for w in clean.walls]
    assert [s.name for s in hard.spaces] == [s.name for s in clean.spaces]
    kept = [e.cls for e in hard.elements if e.info.get("kind") != "flying"]
    assert kept == [e.cls for e in clean.elements]
    assert any(e.info.get("kind") == "flying" for e in hard.elements)
    doc = hard.ground_truth()
    assert doc["building"]["hardness"] == {"registration": 1.0, "artefacts": 1.0}
    assert all("registration" in s and s["scanned"] for s in doc["spaces"])


def test_levels_scale_a_difficulty():
    """Level 2 registration moves the scans further than level 0.5 (the same draws, scaled)."""
    def offsets(level):
        b = plan_building(4, area_m2=300, density=60, hardness={"registration": level})
        return np.array([math.hypot(*s.registration[:2]) for s in b.spaces])
    assert np.all(offsets(2.0) >= offsets(0.5) - 1e-12) and offsets(2.0).sum() > 3 * offsets(0.5).sum()
