"""Pieces of the difficulties: hallway bottlenecks leave a passage, piles of boxes fill the rooms."""
from __future__ import annotations

import numpy as np

from engine.synth import plan_building


def test_hallway_bottlenecks_leave_a_passage():
    b = plan_building(3, area_m2=900, density=60, hardness={"bottlenecks": 2.0})
    found = 0
    for s in b.spaces:
        if s.type != "hallway":
            continue
        lo, hi = s.footprint.min(0), s.footprint.max(0)
        across = int(np.argmin(hi - lo))
        pieces = [e for e in s.elements if e.cls in ("column", "bookcase") and not e.info.get("kind") == "cabinet"]
        for e in pieces:
            box = e.prims[0]
            a = box.center[across] - box.size[across] / 2 - lo[across]
            c = hi[across] - (box.center[across] + box.size[across] / 2)
            assert max(a, c) >= 1.0 - 1e-6 or min(a, c) < 0.01  # a passage beside it (piers: between the pair)
            found += 1
        piers = [e for e in s.elements if e.cls == "column" and e.info.get("engaged")]
        by_pos = {}
        for e in piers:
            by_pos.setdefault(round(float(e.prims[0].center[1 - across]), 6), []).append(e.prims[0])
        for pair in by_pos.values():
            if len(pair) == 2:
                inner = sorted((p.center[across] - p.size[across] / 2, p.center[across] + p.size[across] / 2)
                               for p in pair)
                assert inner[1][0] - inner[0][1] >= 1.0 - 1e-6
    assert found >= 3


def test_piles_of_boxes_in_most_rooms():
    b = plan_building(3, area_m2=600, density=60, hardness="clutter")
    clean = plan_building(3, area_m2=600, density=60)
    piles = [e for e in b.elements if e.info.get("kind") == "boxes"]
    rooms = [s for s in b.spaces if s.type not in ("hallway", "lobby")]
    assert len({e.space for e in piles}) >= 0.6 * len(rooms)
    tops = [max(p.center[2] + p.size[2] / 2 for p in e.prims) - b.spaces[e.space].z0 for e in piles]
    assert max(tops) > 1.4 and min(tops) >= 0.3
    assert sum(e.cls == "clutter" for e in b.elements) > sum(e.cls == "clutter" for e in clean.elements) + 20
