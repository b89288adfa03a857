"""The held-out evaluation's helpers: the foreign buildings' ground truth as our evaluator takes it."""
from __future__ import annotations

import json
import pathlib

import pytest

from benchmarks.shipped_model import foreign_ground_truth
from tiles.classes import ELEMENT_CLASSES

FOREIGN = pathlib.Path(__file__).resolve().parents[2].parent / "shared" / "foreign"


def test_foreign_ground_truth_keeps_every_element_class_and_leaves_out_difficult_and_clutter(tmp_path):
    doc = {"elements": [
        {"class": "board", "space": 3, "center": [1, 2, 3], "size": [1, 0.02, 1], "yaw": 0.5, "difficult": False},
        {"class": "wall", "space": 3, "center": [0, 0, 0], "size": [4, 0.02, 3], "yaw": 0.0, "difficult": True},
        {"class": "clutter", "space": 3, "center": [0, 0, 0], "size": [1, 1, 1], "yaw": 0.0, "difficult": False},
        {"class": "ceiling", "space": 4, "center": [0, 0, 3], "size": [4, 4, 0.02], "yaw": 0.0}]}
    (tmp_path / "gt.json").write_text(json.dumps(doc))
    got = foreign_ground_truth(str(tmp_path))
    assert [(g["class_code"], g["space"]) for g in got] == [(ELEMENT_CLASSES.index("board"), 3),
                                                            (ELEMENT_CLASSES.index("ceiling"), 4)]


def test_the_foreign_buildings_classes_are_all_known():
    if not FOREIGN.is_dir():
        pytest.skip(f"{FOREIGN} is absent (the foreign test buildings)")
    for gt in sorted(FOREIGN.glob("*/gt.json")):
        doc = json.loads(gt.read_text())
        want = {e["class"] for e in doc["elements"] if not e.get("difficult") and e["class"] != "clutter"}
        got = {ELEMENT_CLASSES[g["class_code"]] for g in foreign_ground_truth(str(gt.parent))}
        assert got == want and "board" in got
