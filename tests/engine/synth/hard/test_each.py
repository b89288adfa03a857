"""Each difficulty alone on a small building: it is there, and the ground truth stays exact (issue 8)."""
from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from engine.synth import plan_building, scan_building
from engine.synth.hard.hardness import NAMES

SEED, AREA, FLOORS, DENSITY = 9, 320, 2, 40


def _mod90(angle: float) -> float:
    """Distance of an angle (degrees) from the nearest multiple of 90."""
    return abs((angle + 45.0) % 90.0 - 45.0)


def _wall_angle(w) -> float:
    return math.degrees(math.atan2(w.direction[1], w.direction[0]))


def _kinds(b) -> set:
    return {e.info.get("kind") for e in b.elements}


#: Per difficulty: is it in the building ``b`` (scanned into ``cols``), compared with the clean one ``c``?
PRESENT: dict[str, Callable] = {
    "registration": lambda b, cols, c: any(np.linalg.norm(s["registration"]["offset"]) > 1e-4
                                           for s in b.ground_truth()["spaces"]),
    "glass": lambda b, cols, c: any(w.material == "glass" for w in b.walls),
    "unscanned": lambda b, cols, c: any(not s.scanned and not np.any(cols["gt_space"] == s.id) for s in b.spaces),
    "hidden_walls": lambda b, cols, c: any(w.lined for w in b.walls) and "cabinet" in _kinds(b),
    "wing": lambda b, cols, c: any(s.axis != 0.0 for s in b.spaces),
    "oblique": lambda b, cols, c: any(_mod90(_wall_angle(w)) > 1.0 for w in b.walls),
    "bottlenecks": lambda b, cols, c: (sum(e.cls == "column" for e in b.elements)
                                       > sum(e.cls == "column" for e in c.elements)),
    "open_plan": lambda b, cols, c: "partition" in _kinds(b),
    "walls": lambda b, cols, c: any(w.thickness < 0.1 or w.thickness > 0.35 for w in b.walls
                                    if w.kind == "interior"),
    "clutter": lambda b, cols, c: "boxes" in _kinds(b),
    "stairs": lambda b, cols, c: any(s.type == "stairs" for s in b.spaces) and "stairs" in _kinds(b),
    "artefacts": lambda b, cols, c: "flying" in _kinds(b) and np.any(cols["gt_space"] < 0),
}


@pytest.fixture(scope="module")
def clean():
    return plan_building(SEED, area_m2=AREA, floors=FLOORS, density=DENSITY)


def test_every_difficulty_has_a_check():
    assert set(PRESENT) == set(NAMES)


@pytest.mark.parametrize("name", NAMES)
def test_each_difficulty_alone_is_present_and_the_ground_truth_exact(name, clean, helpers):
    b = plan_building(SEED, area_m2=AREA, floors=FLOORS, density=DENSITY, hardness=name)
    cols = scan_building(b)
    assert b.ground_truth()["building"]["hardness"] == {name: 1.0}
    assert PRESENT[name](b, cols, clean), f"{name} is not in the building"
    # the ground truth: every point has a class; a point of an element lies in its box, space and class
    doc = b.ground_truth()
    els = {e["id"]: e for e in doc["elements"]}
    inst = cols["gt_instance"]
    assert np.all((cols["gt_class"] >= 0) & (cols["gt_class"] <= 12))
    ok = inst >= 0
    assert np.all(cols["gt_space"][ok] >= 0) and np.all(cols["gt_space"][~ok] == -1)
    if name != "artefacts":
        assert ok.all()  # only reflections are outside every element and space
    P = helpers.xyz(cols)
    order = np.argsort(inst, kind="stable")
    si = inst[order]
    cuts = np.flatnonzero(np.r_[True, si[1:] != si[:-1], True])
    for a, z in zip(cuts[:-1], cuts[1:]):
        if si[a] < 0:
            continue
        e = els[int(si[a])]
        sel = order[a:z]
        assert helpers.in_box(P[sel], e).all(), (name, e["class"], e.get("kind"))
        assert np.all(cols["gt_space"][sel] == e["space"]) and np.all(cols["gt_class"][sel] == e["class_code"])
