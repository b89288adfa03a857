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


def test_tight_boxes_are_the_tightest_boxes_of_each_elements_points(tmp_path):
    import numpy as np

    from benchmarks.shipped_model import tight_boxes
    from engine.synth import generate
    from tiles.store import open_store

    generate(str(tmp_path / "b.zarr"), seed=3, rooms=2, density=80)
    st = open_store(str(tmp_path / "b.zarr"))
    elements = st.doc("ground_truth")["elements"]
    tight = {e["id"]: e for e in tight_boxes(st, elements)}
    xyz = np.concatenate([st.xyz(t, local=False) for t in st.tiles])
    inst = np.concatenate([st.read(t, ["gt_instance"])["gt_instance"] for t in st.tiles])
    checked = 0
    for e in elements:
        p = xyz[inst == e["id"]]
        if len(p) < 2:
            continue
        t = tight[e["id"]]
        c, s = np.cos(t["yaw"]), np.sin(t["yaw"])
        q = p - np.asarray(t["center"])
        local = np.column_stack([c * q[:, 0] + s * q[:, 1], -s * q[:, 0] + c * q[:, 1], q[:, 2]])
        half = np.asarray(t["size"]) / 2
        assert np.all(np.abs(local) <= half + 1e-9)  # holds every point
        np.testing.assert_allclose(np.abs(local).max(axis=0), half, atol=1e-9)  # and touches them on every axis
        assert np.all(np.asarray(t["size"]) <= np.asarray(e["size"]) + 1e-9)  # never larger than the generator's
        checked += 1
    assert checked > 20


def test_seen_and_unseen_styles_follow_the_models_training_styles():
    from benchmarks.shipped_model import seen_styles, seen_unseen_line

    assert seen_styles(None) == set()  # the shipped model: classic buildings, no style family
    line = seen_unseen_line({"classic": 80.0, "varied": 70.0, "subsampled": 60.0, "windows": 66.0},
                            {"varied", "windows"})
    assert "seen styles 72.0 (classic, varied, windows), unseen 60.0 (subsampled), gap 12.0" in line
    assert seen_unseen_line({"classic": 80.0}, set()) == ""


def test_the_counts_line_gives_kept_against_true_elements_per_class():
    from benchmarks.shipped_model import counts_line
    from engine.metrics.detection import DetectionEvaluation
    from tiles.classes import ELEMENT_CLASSES

    ev = DetectionEvaluation({c: 0.5 for c in ELEMENT_CLASSES}, {c: 0 for c in ELEMENT_CLASSES} | {"beam": 9},
                             {c: 1 for c in ELEMENT_CLASSES} | {"beam": 285})
    line = counts_line(ev.to_json())
    assert line.startswith("kept/true: ceiling 1/0, floor 1/0") and "beam 285/9" in line
    assert line.count("/") == len(ELEMENT_CLASSES) + 1  # the prefix's and one per class
