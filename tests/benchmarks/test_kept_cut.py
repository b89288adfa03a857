"""The kept set's cut per class (``benchmarks.kept_cut``): matching, F1 and AP at a cut, and the rule."""
from __future__ import annotations

import numpy as np

from benchmarks.kept_cut import at_cut, choose, class_matches, f1, table
from engine.detection.proposals import SURE, Proposal
from tiles.classes import CLASS_CODES


def _prop(cls: str, x: float, score: float, sure: bool = False) -> Proposal:
    p = Proposal(space_id=1, class_code=CLASS_CODES[cls], score=score, position=np.zeros(3), size=np.zeros(3),
                 occupancy=np.zeros((2, 2, 2), bool), center=np.array([x, 0.0, 1.0]),
                 world_size=np.array([1.0, 0.1, 1.0]), yaw=0.0)
    if sure:
        p.extra[SURE] = True
    return p


def _gt(cls: str, x: float) -> dict:
    return {"class": cls, "space": 1, "center": [x, 0.0, 1.0], "size": [1.0, 0.1, 1.0], "yaw": 0.0}


def test_matches_and_counts_at_a_cut():
    props = [_prop("window", 0.0, 2.0), _prop("window", 5.0, -0.7), _prop("window", 9.0, -1.2),
             _prop("window", 0.05, 1.0), _prop("wall", 20.0, -3.0, sure=True)]
    gts = [_gt("window", 0.0), _gt("window", 5.0), _gt("window", 30.0), _gt("wall", 20.0)]
    m = class_matches(props, gts)
    assert list(m["window"]["tp"]) == [True, True, False, False]  # the second box on the first window: a duplicate
    tp, kept, n, ap = at_cut(m["window"], 0.0)
    assert (tp, kept, n) == (1, 2, 3) and np.isclose(ap, 1 / 3)
    tp, kept, n, ap = at_cut(m["window"], -1.0)
    assert (tp, kept, n) == (2, 3, 3) and ap > 1 / 3
    assert at_cut(m["wall"], 0.0)[:3] == (1, 1, 1)  # sure: kept whatever its score
    assert f1([(2, 3, 3, 0.0)]) == 2 * 2 / 6


def test_the_rule_never_raises_a_cut_and_prefers_0_on_ties():
    # family a: a true window at -0.7, family b: a false one at -0.7; more true ones below -1 in a than false in b
    per = {"a": class_matches([_prop("window", 0.0, 1.0), _prop("window", 5.0, -0.7)],
                              [_gt("window", 0.0), _gt("window", 5.0)]),
           "b": class_matches([_prop("window", 0.0, 1.0), _prop("window", 9.0, -0.7)], [_gt("window", 0.0)])}
    assert choose(per, "window", ["a"]) == -1.0  # the nearest to 0 of the cuts that keep the true one
    assert choose(per, "window", ["b"]) == 0.0
    assert choose(per, "window", ["a", "b"]) == -1.0  # pooled: 3 true of 4 kept, 3 elements (F1 0.86 > 0.8)
    assert choose(per, "wall", ["a", "b"]) == 0.0  # no detection, no element: 0
    text, report = table(per)
    assert report["cut"] == {"window": -1.0} and "window" in text and report["classes"]["window"]["left_out"]["b"]["cut"] == -1.0
